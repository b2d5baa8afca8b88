//! Reading a file whole only when it is a regular file of bounded size: a FIFO would block a
//! plain open until a writer comes, a device could stream for ever, and a huge file would be
//! held in memory before anything checked it.

use std::path::Path;

/// Why a file was not read.
pub(crate) enum Unread {
    /// Not a regular file; what it is ([`special_kind`]).
    Special(&'static str),
    /// Larger than allowed; its size in bytes (at least the limit + 1 for one that grew while
    /// read).
    TooLarge(u64),
    /// The system's error.
    Io(std::io::Error),
}

/// What a file that is not a regular file is, for messages.
pub(crate) fn special_kind(file_type: &std::fs::FileType) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    if file_type.is_fifo() {
        "named pipe (FIFO)"
    } else if file_type.is_char_device() {
        "character device"
    } else if file_type.is_block_device() {
        "block device"
    } else if file_type.is_socket() {
        "socket"
    } else if file_type.is_dir() {
        "directory"
    } else {
        "special file"
    }
}

/// The text of the regular file `path` of at most `limit` bytes, refusing anything else without
/// blocking on it or reading it.
pub(crate) fn read_regular(path: &Path, limit: u64) -> Result<String, Unread> {
    use std::io::Read as _;
    use std::os::unix::fs::OpenOptionsExt;
    let check = |metadata: std::fs::Metadata| {
        if !metadata.is_file() {
            return Err(Unread::Special(special_kind(&metadata.file_type())));
        }
        if metadata.len() > limit {
            return Err(Unread::TooLarge(metadata.len()));
        }
        Ok(())
    };
    // Look before opening (opening a socket fails, opening a device may act on it), then check
    // what was opened, in case the path was replaced in between.
    check(std::fs::metadata(path).map_err(Unread::Io)?)?;
    let file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path)
        .map_err(Unread::Io)?;
    check(file.metadata().map_err(Unread::Io)?)?;
    let mut text = String::new();
    // One byte past the limit tells a file that grew while read from one that fits.
    file.take(limit + 1).read_to_string(&mut text).map_err(Unread::Io)?;
    if text.len() as u64 > limit {
        return Err(Unread::TooLarge(text.len() as u64));
    }
    Ok(text)
}
