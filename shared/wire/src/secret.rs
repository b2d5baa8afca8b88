//! A run's secret: 16 random bytes its learner makes when it starts, which every message of its
//! workers carries. The learner refuses a worker without it, so a process of the same user that
//! only knows the run's name (visible in /dev/shm and `ps`) cannot join and report made-up
//! outcomes, and neither can a worker left over from an earlier run of the same name.
//!
//! Workers get it in one of two ways (docs/PROTOCOL.md, "The run's secret"):
//! - a worker the fleet starts finds it in [`SECRET_ENV`], beside the run's name;
//! - a worker started by hand reads the run's secret file, `/dev/shm/acps_<run>_secret`, which
//!   the learner writes (mode 0600, its user's alone) once it serves the run, and which goes
//!   with the run's other files.
//!
//! What it does not do: a process of the same user can read that file, or a started worker's
//! environment, as it can read the learner's memory. The secret tells the run's workers from
//! processes that were not given it; the user's account remains the boundary of trust.

#[cfg(doc)]
use crate::ipc::RUN_ENV;
use crate::ipc::RunName;
use std::io::{Read as _, Write as _};
use std::os::unix::fs::{MetadataExt as _, OpenOptionsExt as _};
use std::path::{Path, PathBuf};

/// Bytes of a run's secret.
pub const SECRET_BYTES: usize = 16;

/// The environment variable that gives a worker the fleet started the secret of the run named in
/// [`RUN_ENV`], as [`SECRET_BYTES`] * 2 hexadecimal digits.
pub const SECRET_ENV: &str = "ACPS_RUN_SECRET";

/// A run's secret. Its `Debug` shows no byte of it.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct RunSecret([u8; SECRET_BYTES]);

impl std::fmt::Debug for RunSecret {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("RunSecret(..)")
    }
}

/// Where a worker found the secret it sends, for the message that explains a refusal.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum SecretOrigin {
    /// [`SECRET_ENV`], set for the run named in [`RUN_ENV`].
    Environment,
    /// The run's secret file.
    File(PathBuf),
    /// Neither: the worker sends none (all zeros), and a learner of this build refuses it.
    Missing(PathBuf),
}

impl std::fmt::Display for SecretOrigin {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Environment => write!(f, "this worker sent the secret in {SECRET_ENV}"),
            Self::File(path) => write!(f, "this worker sent the secret in {}", path.display()),
            Self::Missing(path) => write!(
                f,
                "this worker found no secret ({SECRET_ENV} is not set for this run and {} does not exist)",
                path.display()
            ),
        }
    }
}

/// A secret that could not be made, written or read.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SecretError {
    /// The system gave no random bytes.
    #[error("making run '{run}''s secret from /dev/urandom: {reason}")]
    Random {
        /// The run.
        run: RunName,
        /// The system's reason.
        reason: String,
    },
    /// The secret file could not be written, or another user's file is in its place.
    #[error("writing run '{run}''s secret to {path}: {reason}")]
    Write {
        /// The run.
        run: RunName,
        /// The secret file.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
    /// The secret file is not one this user's learner wrote: another user's, not a regular
    /// file, readable by others, or not a secret.
    #[error("reading run '{run}''s secret from {path}: {reason}")]
    Read {
        /// The run.
        run: RunName,
        /// The secret file.
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
    /// [`SECRET_ENV`] holds no secret.
    #[error("{SECRET_ENV}: must be {} hexadecimal digits (the run's secret, set by the fleet that starts the worker), got {got}", SECRET_BYTES * 2)]
    Environment {
        /// What it holds, described without showing it.
        got: String,
    },
}

impl RunSecret {
    /// A fresh secret for `run`, from the system's random source.
    pub fn generate(run: &RunName) -> Result<Self, SecretError> {
        random_bytes().map(Self).map_err(|error| SecretError::Random {
            run: run.clone(),
            reason: error.to_string(),
        })
    }

    /// Its bytes.
    pub fn bytes(&self) -> [u8; SECRET_BYTES] {
        self.0
    }

    /// Whether a message's `bytes` are this secret. Every byte is compared, whatever the first
    /// difference, so the time taken says nothing of where it is.
    pub fn matches(&self, bytes: &[u8; SECRET_BYTES]) -> bool {
        self.0.iter().zip(bytes).fold(0, |differ, (a, b)| differ | (a ^ b)) == 0
    }

    /// As [`SECRET_ENV`] and the secret file hold it: lowercase hexadecimal digits.
    pub fn to_hex(&self) -> String {
        to_hex(&self.0)
    }

    /// The secret written as [`to_hex`](Self::to_hex) writes it (surrounding whitespace
    /// ignored), `None` for anything else.
    pub fn from_hex(text: &str) -> Option<Self> {
        from_hex(text.trim()).map(Self)
    }

    /// Where the learner of `run` writes its secret for workers started by hand.
    pub fn path(run: &RunName) -> PathBuf {
        PathBuf::from(format!("/dev/shm/{}secret", run.prefix()))
    }

    /// Write the secret file of `run`, readable and writable by this user alone. It replaces the
    /// file of a dead earlier run of the name whole (written beside it, then renamed), so a
    /// worker never reads half of one; another user's file in its place is an error.
    pub fn publish(&self, run: &RunName) -> Result<(), SecretError> {
        let path = Self::path(run);
        write_private(&path, &format!("{}\n", self.to_hex()), Replace::Whole).map_err(|reason| SecretError::Write {
            run: run.clone(),
            path: path.clone(),
            reason,
        })
    }

    /// The secret a worker joining `run` sends, and where it found it: [`SECRET_ENV`] when
    /// [`RUN_ENV`] names `run` (a worker the fleet started), else the run's secret file, else
    /// none ([`SecretOrigin::Missing`]).
    pub fn for_worker(run: &RunName) -> Result<(Option<Self>, SecretOrigin), SecretError> {
        if RunName::from_env().ok().flatten().as_ref() == Some(run)
            && let Ok(text) = std::env::var(SECRET_ENV)
        {
            let secret = Self::from_hex(&text).ok_or_else(|| SecretError::Environment {
                got: format!("{} characters", text.len()),
            })?;
            return Ok((Some(secret), SecretOrigin::Environment));
        }
        let path = Self::path(run);
        match read_file(run, &path)? {
            Some(secret) => Ok((Some(secret), SecretOrigin::File(path))),
            None => Ok((None, SecretOrigin::Missing(path))),
        }
    }
}

/// The secret in `path`, `None` when there is no file.
fn read_file(run: &RunName, path: &Path) -> Result<Option<RunSecret>, SecretError> {
    let refuse = |reason: String| SecretError::Read {
        run: run.clone(),
        path: path.to_path_buf(),
        reason,
    };
    let Some(text) = read_private(path).map_err(refuse)? else {
        return Ok(None);
    };
    RunSecret::from_hex(&text).map(Some).ok_or_else(|| {
        refuse(format!(
            "it holds {} bytes, not {} hexadecimal digits",
            text.len(),
            SECRET_BYTES * 2
        ))
    })
}

/// `N` bytes from the system's random source.
pub fn random_bytes<const N: usize>() -> std::io::Result<[u8; N]> {
    let mut bytes = [0; N];
    std::fs::File::open("/dev/urandom").and_then(|mut random| random.read_exact(&mut bytes))?;
    Ok(bytes)
}

/// `bytes` as lowercase hexadecimal digits.
pub fn to_hex(bytes: &[u8]) -> String {
    bytes.iter().map(|byte| format!("{byte:02x}")).collect()
}

/// The `N` bytes `text` writes in hexadecimal digits, `None` for anything else.
pub fn from_hex<const N: usize>(text: &str) -> Option<[u8; N]> {
    if text.len() != N * 2 || !text.is_ascii() {
        return None;
    }
    let mut bytes = [0; N];
    for (byte, pair) in bytes.iter_mut().zip(text.as_bytes().chunks(2)) {
        *byte = u8::from_str_radix(std::str::from_utf8(pair).ok()?, 16).ok()?;
    }
    Some(bytes)
}

/// Most bytes a private file holds: a secret or a key is one short line.
const PRIVATE_FILE_LIMIT: u64 = 256;

/// The text of a file only this user may read and write (a secret, a key): `None` when there
/// is none, and why not when it is not a regular file, belongs to another user, is open to
/// others or is longer than a secret is.
pub fn read_private(path: &Path) -> Result<Option<String>, String> {
    let metadata = match std::fs::symlink_metadata(path) {
        Ok(metadata) => metadata,
        Err(error) if error.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(error) => return Err(error.to_string()),
    };
    // Checked before it is opened: opening a FIFO would block, and a secret another user could
    // have written, or can read, is none.
    if !metadata.file_type().is_file() {
        return Err("not a regular file".into());
    }
    if metadata.uid() != current_user() {
        return Err(format!(
            "it belongs to user {}, not this process's user {}",
            metadata.uid(),
            current_user()
        ));
    }
    if metadata.mode() & 0o077 != 0 {
        return Err(format!(
            "its mode is {:o}: other users may read or change it (acps writes 600)",
            metadata.mode() & 0o777
        ));
    }
    let mut text = String::new();
    // One byte beyond the limit: a longer file is refused, not cut.
    match std::fs::File::open(path).and_then(|file| file.take(PRIVATE_FILE_LIMIT + 1).read_to_string(&mut text)) {
        Ok(read) if read as u64 > PRIVATE_FILE_LIMIT => Err(format!(
            "longer than the {PRIVATE_FILE_LIMIT} bytes a secret or key takes"
        )),
        Ok(_) => Ok(Some(text)),
        // Removed between the look and the read.
        Err(error) if error.kind() == std::io::ErrorKind::NotFound => Ok(None),
        Err(error) => Err(error.to_string()),
    }
}

/// How [`write_private`] treats a file already there.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Replace {
    /// Replace it whole (written beside it, then renamed), unless another user's.
    Whole,
    /// Leave it: an error.
    Never,
}

/// Write `text` to `path` readable and writable by this user alone, and why not.
pub fn write_private(path: &Path, text: &str, replace: Replace) -> Result<(), String> {
    if let Ok(existing) = std::fs::symlink_metadata(path) {
        if replace == Replace::Never {
            return Err("a file is already there".into());
        }
        if existing.uid() != current_user() {
            return Err(format!(
                "a file of user {} is in its place (another user's run of the same name?)",
                existing.uid()
            ));
        }
    }
    let written = PathBuf::from(format!("{}.new", path.display()));
    let _ = std::fs::remove_file(&written);
    let created = std::fs::OpenOptions::new()
        .write(true)
        .create_new(true)
        .mode(0o600)
        .open(&written)
        .and_then(|mut file| file.write_all(text.as_bytes()));
    let renamed = created.and_then(|()| match replace {
        Replace::Whole => std::fs::rename(&written, path),
        // A link fails where a file appeared meanwhile, where a rename would replace it.
        Replace::Never => std::fs::hard_link(&written, path).and_then(|()| std::fs::remove_file(&written)),
    });
    renamed.map_err(|error| {
        let _ = std::fs::remove_file(&written);
        error.to_string()
    })
}

/// This process's effective user.
pub(crate) fn current_user() -> u32 {
    // SAFETY: geteuid has no preconditions and cannot fail.
    unsafe { libc::geteuid() }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt as _;

    fn run(name: &str) -> RunName {
        RunName::new(&format!("{name}-{}", std::process::id())).unwrap()
    }

    #[test]
    fn a_secret_survives_hex_and_a_different_one_does_not_match() {
        let run = run("secret-hex");
        let secret = RunSecret::generate(&run).unwrap();
        let other = RunSecret::generate(&run).unwrap();
        assert_ne!(secret, other, "two draws of 128 random bits");
        assert_eq!(RunSecret::from_hex(&format!(" {}\n", secret.to_hex())), Some(secret));
        assert!(secret.matches(&secret.bytes()));
        assert!(!secret.matches(&other.bytes()));
        assert!(!secret.matches(&[0; SECRET_BYTES]));
        for bad in ["", "00", &"g".repeat(32), &"0".repeat(33), &"é".repeat(16)] {
            assert_eq!(RunSecret::from_hex(bad), None, "{bad:?}");
        }
        assert_eq!(format!("{secret:?}"), "RunSecret(..)");
    }

    #[test]
    fn a_published_secret_is_its_users_alone_and_workers_read_it_back() {
        let run = run("secret-file");
        let path = RunSecret::path(&run);
        assert_eq!(
            RunSecret::for_worker(&run).unwrap(),
            (None, SecretOrigin::Missing(path.clone()))
        );
        let secret = RunSecret::generate(&run).unwrap();
        secret.publish(&run).unwrap();
        assert_eq!(std::fs::metadata(&path).unwrap().permissions().mode() & 0o777, 0o600);
        assert_eq!(
            RunSecret::for_worker(&run).unwrap(),
            (Some(secret), SecretOrigin::File(path.clone()))
        );
        // A later run of the name replaces it.
        let later = RunSecret::generate(&run).unwrap();
        later.publish(&run).unwrap();
        assert_eq!(RunSecret::for_worker(&run).unwrap().0, Some(later));
        // A file others may read is no secret; nor is one that holds something else.
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o644)).unwrap();
        let error = RunSecret::for_worker(&run).unwrap_err().to_string();
        assert!(error.contains("its mode is 644"), "{error}");
        // Never replacing a file: a key another process made stays.
        let kept = std::fs::read(&path).unwrap();
        assert_eq!(
            write_private(&path, "other", Replace::Never),
            Err("a file is already there".to_string())
        );
        assert_eq!(std::fs::read(&path).unwrap(), kept);
        std::fs::write(&path, "not a secret").unwrap();
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o600)).unwrap();
        let error = RunSecret::for_worker(&run).unwrap_err().to_string();
        assert_eq!(
            error,
            format!(
                "reading run '{run}''s secret from {}: it holds 12 bytes, not 32 hexadecimal digits",
                path.display()
            )
        );
        std::fs::write(&path, "0".repeat(1000)).unwrap();
        let error = RunSecret::for_worker(&run).unwrap_err().to_string();
        assert!(
            error.ends_with("longer than the 256 bytes a secret or key takes"),
            "{error}"
        );
        std::fs::remove_file(&path).unwrap();
        std::fs::create_dir(&path).unwrap();
        let error = RunSecret::for_worker(&run).unwrap_err().to_string();
        assert!(error.ends_with("not a regular file"), "{error}");
        std::fs::remove_dir(&path).unwrap();
        assert!(!Path::new(&format!("{}.new", path.display())).exists());
    }
}
