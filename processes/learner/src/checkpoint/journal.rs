//! Record files: what a learner recorded ([`Records`]: episodes, updates, complete evaluations),
//! appended as the run goes, so that a checkpoint holds the learner's bounded state and only
//! where its record file ended ([`JournalMark`]), never the history itself.
//!
//! # Format (version 1)
//! A 32-byte header laid out as a checkpoint's first 32 bytes (magic `ACPSRECS`, version u32,
//! reserved u32 = 0, run identity u64, job u64; little-endian), then one frame per record:
//!
//! | bytes | field |
//! |---|---|
//! | 1 | kind: 0 episode, 1 update, 2 evaluation |
//! | 4 | payload length (u32, little-endian) |
//! | n | payload: the [`crate::Episode`], [`crate::UpdateRecord`] or [`crate::Evaluation`] in bincode 2's standard encoding |
//!
//! A [`JournalMark`] is the file's length, the FNV-1a 64 hash of all its bytes and the records
//! of each kind up to that length. Resuming from a mark checks the header (another file, run or
//! job), that the file reaches the mark ("truncated") and that its bytes up to the mark hash to
//! the mark's ("corrupted"), then cuts what was written after the checkpoint and appends from
//! there. Every error names the file.

use super::{CheckpointDecodeError, Stamp, check_kind, check_stamp};
use crate::learner::{Episode, Evaluation, RecordCounts, Records, UpdateRecord};
use acps_shared::{FNV_OFFSET, fnv1a};
use serde::{Deserialize, Serialize};
use std::fs::File;
use std::io::{BufReader, BufWriter, Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

/// The first eight bytes of every record file.
pub const JOURNAL_MAGIC: [u8; 8] = *b"ACPSRECS";
/// The record file format this build writes and reads.
pub const JOURNAL_VERSION: u32 = 2;
/// Header length in bytes.
pub const JOURNAL_HEADER_LEN: usize = 32;
/// Frame header length in bytes: the kind and the payload length.
const FRAME_LEN: usize = 5;

/// Where a record file ended when a checkpoint was taken.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct JournalMark {
    /// The file's length in bytes.
    pub len: u64,
    /// FNV-1a 64 of its first `len` bytes.
    pub hash: u64,
    /// The records of each kind in them.
    pub records: RecordCounts,
}

/// Why a record file cannot be written, resumed or read; names the file.
#[derive(Debug, thiserror::Error)]
pub enum JournalError {
    /// Creating, reading, writing or cutting the file failed.
    #[error("record file {}: {source}", path.display())]
    Io {
        /// The record file.
        path: PathBuf,
        /// What failed.
        source: std::io::Error,
    },
    /// The file is not the intact record file of this job up to the checkpoint's mark.
    #[error("record file {}: {source}", path.display())]
    Decode {
        /// The record file.
        path: PathBuf,
        /// What is wrong with it.
        source: CheckpointDecodeError,
    },
}

#[derive(Clone, Copy)]
enum Kind {
    Episode = 0,
    Update = 1,
    Evaluation = 2,
}

/// Appends a learner's records to its record file.
///
/// ```
/// use acps_learner::checkpoint::{Stamp, journal::{self, JournalWriter}};
/// use acps_learner::{Episode, Records};
///
/// let path = std::env::temp_dir().join(format!("acps-doc-journal-{}.records", std::process::id()));
/// let stamp = Stamp { identity: 7, job: 0 };
/// let mut writer = JournalWriter::create(&path, stamp)?;
/// let episode = Episode { arm: Some(1), context: vec![0.5], reward: -2.0 };
/// writer.append(&Records { episodes: vec![episode.clone()], ..Default::default() })?;
/// let mark = writer.flush()?; // goes into the checkpoint
/// assert_eq!(journal::read(&path, stamp, &mark)?.episodes, [episode]);
/// # std::fs::remove_file(&path)?;
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub struct JournalWriter {
    path: PathBuf,
    file: BufWriter<File>,
    len: u64,
    hash: u64,
    records: RecordCounts,
    scratch: Vec<u8>,
}

fn config() -> bincode::config::Configuration {
    bincode::config::standard()
}

fn header(stamp: Stamp) -> [u8; JOURNAL_HEADER_LEN] {
    let mut bytes = [0; JOURNAL_HEADER_LEN];
    bytes[..8].copy_from_slice(&JOURNAL_MAGIC);
    bytes[8..12].copy_from_slice(&JOURNAL_VERSION.to_le_bytes());
    bytes[16..24].copy_from_slice(&stamp.identity.to_le_bytes());
    bytes[24..32].copy_from_slice(&stamp.job.to_le_bytes());
    bytes
}

impl JournalWriter {
    /// A new, empty record file at `path` (an old one is replaced).
    pub fn create(path: &Path, stamp: Stamp) -> Result<Self, JournalError> {
        let file = File::create(path).map_err(io(path))?;
        let mut writer = Self::at(path, file, 0, FNV_OFFSET, RecordCounts::default());
        writer.write(&header(stamp))?;
        Ok(writer)
    }

    /// Continue the record file at `path` from `mark`, the checkpoint's: refused when the file
    /// is of another run or job, shorter than the mark or not the bytes the mark hashed; what
    /// follows the mark (written after the checkpoint) is cut.
    pub fn resume(path: &Path, stamp: Stamp, mark: &JournalMark) -> Result<Self, JournalError> {
        let mut file = open_file(path, std::fs::OpenOptions::new().read(true).write(true))?;
        scan(path, &mut file, stamp, mark, |_, _, _| Ok(()))?;
        file.set_len(mark.len).map_err(io(path))?;
        file.seek(SeekFrom::End(0)).map_err(io(path))?;
        Ok(Self::at(path, file, mark.len, mark.hash, mark.records))
    }

    fn at(path: &Path, file: File, len: u64, hash: u64, records: RecordCounts) -> Self {
        Self {
            path: path.to_path_buf(),
            file: BufWriter::with_capacity(1 << 16, file),
            len,
            hash,
            records,
            scratch: Vec::new(),
        }
    }

    /// Append `records` (buffered: on disk after the next [`flush`](Self::flush)).
    pub fn append(&mut self, records: &Records) -> Result<(), JournalError> {
        for episode in &records.episodes {
            self.frame(Kind::Episode, episode)?;
        }
        for update in &records.updates {
            self.frame(Kind::Update, update)?;
        }
        for evaluation in &records.evaluations {
            self.frame(Kind::Evaluation, evaluation)?;
        }
        self.records.add(RecordCounts::of(records));
        Ok(())
    }

    fn frame(&mut self, kind: Kind, record: &impl Serialize) -> Result<(), JournalError> {
        let mut scratch = std::mem::take(&mut self.scratch);
        scratch.clear();
        scratch.extend_from_slice(&[kind as u8, 0, 0, 0, 0]);
        bincode::serde::encode_into_std_write(record, &mut scratch, config()).expect("records always encode");
        let payload = u32::try_from(scratch.len() - FRAME_LEN).expect("a record is smaller than 4 GiB");
        scratch[1..FRAME_LEN].copy_from_slice(&payload.to_le_bytes());
        let written = self.write(&scratch);
        self.scratch = scratch;
        written
    }

    fn write(&mut self, bytes: &[u8]) -> Result<(), JournalError> {
        self.file.write_all(bytes).map_err(io(&self.path))?;
        self.len += bytes.len() as u64;
        self.hash = fnv1a(self.hash, bytes);
        Ok(())
    }

    /// Write out what is buffered and return where the file now ends, for a checkpoint. Not
    /// synced to disk, as checkpoints are not: after a crash of the machine a damaged file is
    /// refused on reading.
    pub fn flush(&mut self) -> Result<JournalMark, JournalError> {
        self.file.flush().map_err(io(&self.path))?;
        Ok(JournalMark {
            len: self.len,
            hash: self.hash,
            records: self.records,
        })
    }

    /// The record file.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> JournalError + '_ {
    move |source| JournalError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Read the first `mark.len` bytes of `file` through a buffer, checking them against `stamp`
/// and `mark` (header, length, hash), and hand every record frame to `frame` (its kind, payload
/// and offset; an `Err` is a corrupted record) as it goes. Nothing `frame` made may be used
/// unless this returns `Ok`: the hash is checked at the end.
fn scan(
    path: &Path,
    file: &mut File,
    stamp: Stamp,
    mark: &JournalMark,
    mut frame: impl FnMut(u8, &[u8], u64) -> Result<(), String>,
) -> Result<(), JournalError> {
    let decode = |source| JournalError::Decode {
        path: path.to_path_buf(),
        source,
    };
    let len = file.metadata().map_err(io(path))?.len();
    let mut reader = BufReader::with_capacity(1 << 16, Read::by_ref(file).take(mark.len));
    let mut header = Vec::with_capacity(JOURNAL_HEADER_LEN);
    Read::by_ref(&mut reader)
        .take(JOURNAL_HEADER_LEN as u64)
        .read_to_end(&mut header)
        .map_err(io(path))?;
    check_kind(&header, JOURNAL_MAGIC, JOURNAL_VERSION, JOURNAL_HEADER_LEN).map_err(decode)?;
    check_stamp(&header, stamp).map_err(decode)?;
    if len < mark.len {
        return Err(decode(CheckpointDecodeError::Truncated {
            len,
            expected: mark.len,
        }));
    }
    let corrupt = |what: String| decode(CheckpointDecodeError::Corrupt(what));
    let mut hash = fnv1a(FNV_OFFSET, &header);
    let mut at = JOURNAL_HEADER_LEN as u64;
    let mut payload = Vec::new();
    while at < mark.len {
        let mut head = [0; FRAME_LEN];
        if mark.len - at < FRAME_LEN as u64 {
            return Err(corrupt(format!("a record's header is cut at byte {at}")));
        }
        reader.read_exact(&mut head).map_err(io(path))?;
        let size = u64::from(u32::from_le_bytes(head[1..].try_into().expect("4 bytes")));
        if mark.len - at - (FRAME_LEN as u64) < size {
            return Err(corrupt(format!("the record at byte {at} is cut")));
        }
        payload.resize(size as usize, 0);
        reader.read_exact(&mut payload).map_err(io(path))?;
        hash = fnv1a(fnv1a(hash, &head), &payload);
        frame(head[0], &payload, at).map_err(|what| corrupt(format!("the record at byte {at}: {what}")))?;
        at += FRAME_LEN as u64 + size;
    }
    if hash != mark.hash {
        return Err(corrupt(format!(
            "its first {} bytes are not the ones the checkpoint recorded",
            mark.len
        )));
    }
    Ok(())
}

/// The record file at `path` opened with `options`, if it is a regular file (or a link to one):
/// a FIFO would block its reader, a device such as /dev/zero never end.
fn open_file(path: &Path, options: &std::fs::OpenOptions) -> Result<File, JournalError> {
    let metadata = std::fs::metadata(path).map_err(io(path))?;
    super::regular(&metadata).map_err(|source| JournalError::Decode {
        path: path.to_path_buf(),
        source,
    })?;
    options.open(path).map_err(io(path))
}

/// The records in the record file at `path` up to `mark`, checked as
/// [`JournalWriter::resume`] checks it; read through a buffer, so only the records take memory.
pub fn read(path: &Path, stamp: Stamp, mark: &JournalMark) -> Result<Records, JournalError> {
    let mut records = Records::default();
    read_each(path, stamp, mark, |record| match record {
        Record::Episode(episode) => records.episodes.push(episode),
        Record::Update(update) => records.updates.push(update),
        Record::Evaluation(evaluation) => records.evaluations.push(evaluation),
    })?;
    Ok(records)
}

/// One record of a record file.
#[derive(Debug, Clone, PartialEq)]
pub enum Record {
    /// A consumed training episode.
    Episode(Episode),
    /// A C-REPS update.
    Update(UpdateRecord),
    /// A complete evaluation.
    Evaluation(Evaluation),
}

/// [`read`], handing each record to `each` as it is read (in the file's order) instead of
/// collecting them, for a reader that keeps less of them. `each` must not be trusted with what
/// it saw unless this returns `Ok`: the file's hash is checked at its end.
pub fn read_each(
    path: &Path,
    stamp: Stamp,
    mark: &JournalMark,
    mut each: impl FnMut(Record),
) -> Result<(), JournalError> {
    let mut file = open_file(path, std::fs::OpenOptions::new().read(true))?;
    let mut counts = RecordCounts::default();
    scan(path, &mut file, stamp, mark, |kind, payload, _| {
        let undecodable = |e: bincode::error::DecodeError| e.to_string();
        let record = match kind {
            0 => Record::Episode(decode(payload).map_err(undecodable)?),
            1 => Record::Update(decode(payload).map_err(undecodable)?),
            2 => Record::Evaluation(decode(payload).map_err(undecodable)?),
            kind => return Err(format!("unknown kind {kind}")),
        };
        match record {
            Record::Episode(_) => counts.episodes += 1,
            Record::Update(_) => counts.updates += 1,
            Record::Evaluation(_) => counts.evaluations += 1,
        }
        each(record);
        Ok(())
    })?;
    if counts != mark.records {
        return Err(JournalError::Decode {
            path: path.to_path_buf(),
            source: CheckpointDecodeError::Corrupt(format!(
                "it holds {counts:?}, the checkpoint recorded {:?}",
                mark.records
            )),
        });
    }
    Ok(())
}

fn decode<T: serde::de::DeserializeOwned>(payload: &[u8]) -> Result<T, bincode::error::DecodeError> {
    let (value, used) = bincode::serde::decode_from_slice(payload, config())?;
    if used != payload.len() {
        return Err(bincode::error::DecodeError::OtherString(format!(
            "{} of {} bytes decode",
            used,
            payload.len()
        )));
    }
    Ok(value)
}
