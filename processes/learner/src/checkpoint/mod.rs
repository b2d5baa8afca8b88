//! Checkpoint files: a learner's snapshot and its environment's state, so that a run can be
//! resumed after it was stopped (even by `kill -9`) and end bit for bit as if it never was.
//!
//! # Format (version 7)
//! A 48-byte header, all integers little-endian, then the payload:
//!
//! | offset | bytes | field |
//! |---|---|---|
//! | 0 | 8 | magic `ACPSCKPT` |
//! | 8 | 4 | format version (u32) |
//! | 12 | 4 | reserved, 0 |
//! | 16 | 8 | identity of the run the checkpoint belongs to (u64; the launcher's hash of the experiment's configuration) |
//! | 24 | 8 | job index within the run (u64) |
//! | 32 | 8 | payload length in bytes (u64) |
//! | 40 | 8 | FNV-1a 64 checksum of bytes 0..40 and the payload |
//! | 48 | n | payload: [`Checkpoint`] in bincode 2's standard encoding (serde) |
//!
//! Reading checks, in this order: magic, version, length (a short file is "truncated"),
//! checksum ("corrupted"), identity ("another experiment") and job; every error names the file.
//! The version is raised whenever the payload's layout changes, since bincode is not
//! self-describing. Files are written to a temporary file beside the target and renamed over it,
//! so a process killed during a write leaves the previous checkpoint intact.
//!
//! A run that takes its learner's records as it goes ([`Learner::take_records`]) appends them
//! to a record file ([`journal`]) and keeps in its checkpoint only where that file ended
//! ([`Checkpoint::records`]): the checkpoint costs what the learner's state costs, however long
//! the run.

pub mod journal;

use crate::learner::{Learner, LearnerRestoreError, LearnerSnapshot};
use acps_shared::{Environment, EnvironmentRestoreError, FNV_OFFSET, fnv1a};
use serde::{Deserialize, Serialize};
use std::io::Write;
use std::path::{Path, PathBuf};

/// The first eight bytes of every checkpoint file.
pub const MAGIC: [u8; 8] = *b"ACPSCKPT";
/// The format version this build writes and reads.
pub const FORMAT_VERSION: u32 = 8;
/// Header length in bytes.
pub const HEADER_LEN: usize = 48;

/// What a checkpoint holds.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Checkpoint {
    /// The learner's whole evolving state.
    pub learner: LearnerSnapshot,
    /// The environment's state ([`Environment::save_state`]); empty for environments without.
    pub environment: Vec<u8>,
    /// Where the job's record file ended, for a run that writes its records to one
    /// ([`journal`]); `None` when the learner holds them all.
    pub records: Option<journal::JournalMark>,
}

impl Checkpoint {
    /// The state of `learner` and `environment` now. With an environment that keeps state
    /// between rollouts, take it only when no task is out (in-process runs: between a `tell` and
    /// the next `ask`), since tasks out are performed again after a restore.
    pub fn take(learner: &Learner, environment: &dyn Environment) -> Self {
        Self {
            learner: learner.snapshot(),
            environment: environment.save_state(),
            records: None,
        }
    }

    /// Continue `learner` and `environment`, freshly built as the ones the checkpoint was taken
    /// of, from this checkpoint.
    pub fn apply(self, learner: &mut Learner, environment: &mut dyn Environment) -> Result<(), CheckpointApplyError> {
        learner.restore(self.learner)?;
        Ok(environment.restore_state(&self.environment)?)
    }
}

/// Whose checkpoint a file is: the run's identity and the job's index in it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stamp {
    /// A hash of everything that determines the run's results.
    pub identity: u64,
    /// The job's index within the run.
    pub job: u64,
}

/// Why [`write()`] failed, naming the file.
#[derive(Debug, thiserror::Error)]
#[error("checkpoint {}: {source}", path.display())]
pub struct CheckpointWriteError {
    /// The checkpoint file.
    pub path: PathBuf,
    /// Creating, writing or renaming the file failed.
    pub source: std::io::Error,
}

/// Why [`read`] failed, naming the file.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointReadError {
    /// The file exists but could not be read.
    #[error("checkpoint {}: {source}", path.display())]
    Io {
        /// The checkpoint file.
        path: PathBuf,
        /// What failed.
        source: std::io::Error,
    },
    /// The file is not an intact checkpoint of this job.
    #[error("checkpoint {}: {source}", path.display())]
    Decode {
        /// The checkpoint file.
        path: PathBuf,
        /// What is wrong with its contents.
        source: CheckpointDecodeError,
    },
}

/// Why [`Checkpoint::apply`] failed. The learner is unchanged when the learner's part is
/// refused; the environment's part is applied after it.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum CheckpointApplyError {
    /// The learner refused the snapshot.
    #[error(transparent)]
    Learner(#[from] LearnerRestoreError),
    /// The environment refused its state.
    #[error("environment state: {0}")]
    Environment(#[from] EnvironmentRestoreError),
}

/// Why [`decode`] refuses bytes as a checkpoint of a job.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum CheckpointDecodeError {
    /// The file does not start with [`MAGIC`].
    #[error("not an acps checkpoint (it does not start with the magic bytes \"ACPSCKPT\")")]
    NotACheckpoint,
    /// A record file ([`journal`]) that does not start with [`journal::JOURNAL_MAGIC`].
    #[error("not an acps record file (it does not start with the magic bytes \"ACPSRECS\")")]
    NotARecordFile,
    /// Another format version.
    #[error("format version {found}, but this build reads version {supported} only; start the run afresh")]
    Version {
        /// The file's version.
        found: u32,
        /// The version this build reads.
        supported: u32,
    },
    /// Shorter than its header, or a record file shorter than its checkpoint, says.
    #[error("truncated: {len} bytes, but {expected} bytes were written")]
    Truncated {
        /// The file's length.
        len: u64,
        /// The length it should have (the header alone, if that is cut short).
        expected: u64,
    },
    /// The checksum does not match, or bytes follow the payload.
    #[error("corrupted: {0}")]
    Corrupt(String),
    /// A checkpoint of another run.
    #[error(
        "belongs to another experiment (identity {found:016x}, this one is {expected:016x}): resume with the arguments the run was started with, or use another directory"
    )]
    Foreign {
        /// The file's identity.
        found: u64,
        /// This run's identity.
        expected: u64,
    },
    /// A checkpoint of another job of the same run.
    #[error("belongs to job {found} of this run, not to job {expected}")]
    WrongJob {
        /// The file's job.
        found: u64,
        /// The job it was read for.
        expected: u64,
    },
    /// The payload does not decode (a build with another payload layout under the same version).
    #[error("the payload cannot be decoded: {0}")]
    Payload(String),
    /// Larger than any checkpoint this build writes could be.
    #[error("{len} bytes, more than the {MAX_CHECKPOINT_BYTES} a checkpoint may have")]
    TooLarge {
        /// Its length, or the payload length its header announces.
        len: u64,
    },
    /// Not a regular file (a FIFO, a device, a directory), which reading could block on or
    /// never finish.
    #[error("not a regular file but {0}")]
    NotAFile(&'static str),
}

fn config() -> bincode::config::Configuration {
    bincode::config::standard()
}

/// The most bytes a checkpoint may have. A learner's bounded state takes kilobytes; the
/// largest unbounded ones (a bandit over many arms, ALP-GMM's history, best-per-task memory)
/// reach tens of megabytes over the longest runs a file allows (10,000,000 episodes). Decoding
/// claims no more than this either, so that a forged length cannot ask for exabytes.
pub const MAX_CHECKPOINT_BYTES: u64 = 1 << 30;

/// How a checkpoint's payload is decoded: as written, with every length it claims limited.
fn decode_config() -> bincode::config::Configuration<
    bincode::config::LittleEndian,
    bincode::config::Varint,
    bincode::config::Limit<{ MAX_CHECKPOINT_BYTES as usize }>,
> {
    config().with_limit::<{ MAX_CHECKPOINT_BYTES as usize }>()
}

/// The bytes of a checkpoint file.
pub fn encode(stamp: Stamp, checkpoint: &Checkpoint) -> Vec<u8> {
    let payload = bincode::serde::encode_to_vec(checkpoint, config()).expect("a checkpoint always encodes");
    let mut bytes = Vec::with_capacity(HEADER_LEN + payload.len());
    bytes.extend_from_slice(&MAGIC);
    bytes.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    bytes.extend_from_slice(&0u32.to_le_bytes());
    bytes.extend_from_slice(&stamp.identity.to_le_bytes());
    bytes.extend_from_slice(&stamp.job.to_le_bytes());
    bytes.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    let checksum = fnv1a(fnv1a(FNV_OFFSET, &bytes), &payload);
    bytes.extend_from_slice(&checksum.to_le_bytes());
    bytes.extend_from_slice(&payload);
    bytes
}

/// The checkpoint in `bytes`, if they are a complete, intact checkpoint of `stamp`.
pub fn decode(bytes: &[u8], stamp: Stamp) -> Result<Checkpoint, CheckpointDecodeError> {
    check_kind(bytes, MAGIC, FORMAT_VERSION, HEADER_LEN)?;
    let u64_at = |at: usize| u64::from_le_bytes(bytes[at..at + 8].try_into().expect("8 bytes"));
    let payload_len = u64_at(32);
    if payload_len > MAX_CHECKPOINT_BYTES {
        return Err(CheckpointDecodeError::TooLarge { len: payload_len });
    }
    let expected = (HEADER_LEN as u64).saturating_add(payload_len);
    let len = bytes.len() as u64;
    if len < expected {
        return Err(CheckpointDecodeError::Truncated { len, expected });
    }
    if len > expected {
        return Err(CheckpointDecodeError::Corrupt(format!(
            "{} bytes follow the {payload_len}-byte payload",
            len - expected
        )));
    }
    let payload = &bytes[HEADER_LEN..];
    if fnv1a(fnv1a(FNV_OFFSET, &bytes[..40]), payload) != u64_at(40) {
        return Err(CheckpointDecodeError::Corrupt(
            "the checksum does not match the contents".into(),
        ));
    }
    check_stamp(bytes, stamp)?;
    let (checkpoint, used) = bincode::serde::decode_from_slice::<Checkpoint, _>(payload, decode_config())
        .map_err(|e| CheckpointDecodeError::Payload(e.to_string()))?;
    if used != payload.len() {
        return Err(CheckpointDecodeError::Payload(format!(
            "{} of {} payload bytes decode to a checkpoint",
            used,
            payload.len()
        )));
    }
    Ok(checkpoint)
}

/// The first checks of a checkpoint's or record file's header (their first 32 bytes are laid
/// out alike): the magic, a header of `header_len` bytes, the version.
fn check_kind(bytes: &[u8], magic: [u8; 8], version: u32, header_len: usize) -> Result<(), CheckpointDecodeError> {
    let magic_len = bytes.len().min(magic.len());
    if bytes[..magic_len] != magic[..magic_len] {
        return Err(if magic == MAGIC {
            CheckpointDecodeError::NotACheckpoint
        } else {
            CheckpointDecodeError::NotARecordFile
        });
    }
    if bytes.len() < header_len {
        return Err(CheckpointDecodeError::Truncated {
            len: bytes.len() as u64,
            expected: header_len as u64,
        });
    }
    let found = u32::from_le_bytes(bytes[8..12].try_into().expect("4 bytes"));
    if found != version {
        return Err(CheckpointDecodeError::Version {
            found,
            supported: version,
        });
    }
    Ok(())
}

/// Whose a checkpoint or record file is (bytes 12..32 of a header [`check_kind`] accepted).
fn check_stamp(bytes: &[u8], stamp: Stamp) -> Result<(), CheckpointDecodeError> {
    let u64_at = |at: usize| u64::from_le_bytes(bytes[at..at + 8].try_into().expect("8 bytes"));
    if bytes[12..16] != [0; 4] {
        return Err(CheckpointDecodeError::Corrupt(
            "reserved header bytes are not zero".into(),
        ));
    }
    let (identity, job) = (u64_at(16), u64_at(24));
    if identity != stamp.identity {
        return Err(CheckpointDecodeError::Foreign {
            found: identity,
            expected: stamp.identity,
        });
    }
    if job != stamp.job {
        return Err(CheckpointDecodeError::WrongJob {
            found: job,
            expected: stamp.job,
        });
    }
    Ok(())
}

/// Write `checkpoint` to `path` atomically: into `path` + ".tmp", then renamed over `path`, so a
/// reader, or a process killed at any moment, sees the old file or the new one, never a mix. The
/// file is not synced to disk (that would cost milliseconds per checkpoint); after a crash of
/// the whole machine a damaged file is refused on reading, as truncated or corrupted.
pub fn write(path: &Path, stamp: Stamp, checkpoint: &Checkpoint) -> Result<(), CheckpointWriteError> {
    let bytes = encode(stamp, checkpoint);
    let mut temporary = path.as_os_str().to_owned();
    temporary.push(".tmp");
    let temporary = PathBuf::from(temporary);
    let written = (|| {
        let mut file = std::fs::File::create(&temporary)?;
        file.write_all(&bytes)?;
        std::fs::rename(&temporary, path)
    })();
    written.map_err(|source| CheckpointWriteError {
        path: path.to_path_buf(),
        source,
    })
}

/// The checkpoint at `path` if there is a file, checked against `stamp`; `None` without one.
/// Only a regular file (or a link to one) of at most [`MAX_CHECKPOINT_BYTES`] is read: a FIFO
/// would block the reader, a device such as /dev/zero never end.
pub fn read(path: &Path, stamp: Stamp) -> Result<Option<Checkpoint>, CheckpointReadError> {
    let path_buf = || path.to_path_buf();
    let io = |source| CheckpointReadError::Io {
        path: path_buf(),
        source,
    };
    let decoded = |source| CheckpointReadError::Decode {
        path: path_buf(),
        source,
    };
    let metadata = match std::fs::metadata(path) {
        Ok(metadata) => metadata,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(source) => return Err(io(source)),
    };
    regular(&metadata).map_err(decoded)?;
    if metadata.len() > HEADER_LEN as u64 + MAX_CHECKPOINT_BYTES {
        return Err(decoded(CheckpointDecodeError::TooLarge { len: metadata.len() }));
    }
    let bytes = std::fs::read(path).map_err(io)?;
    decode(&bytes, stamp).map(Some).map_err(decoded)
}

/// Whether a checkpoint or record file is a regular file (or a link to one), which reading
/// neither blocks on (a FIFO) nor never finishes (a device such as /dev/zero).
fn regular(metadata: &std::fs::Metadata) -> Result<(), CheckpointDecodeError> {
    use std::os::unix::fs::FileTypeExt;
    let kind = metadata.file_type();
    if kind.is_file() {
        return Ok(());
    }
    Err(CheckpointDecodeError::NotAFile(if kind.is_dir() {
        "a directory"
    } else if kind.is_fifo() {
        "a FIFO"
    } else if kind.is_char_device() || kind.is_block_device() {
        "a device"
    } else if kind.is_socket() {
        "a socket"
    } else {
        "of another kind"
    }))
}

#[cfg(test)]
mod tests;
