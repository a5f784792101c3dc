//! Atomic file writes, the one way every writer of the workspace puts a file in place: the
//! bytes go to a temporary file beside the destination (`.NAME.PID.tmp`, in the same folder so
//! that the rename stays on one file system), are synced to disk, and the temporary file is
//! renamed over the destination. A reader sees the old file or the new one, never a part; a
//! failed write removes its temporary file and leaves the destination as it was.

use std::fs::File;
use std::io;
use std::path::{Path, PathBuf};

/// The temporary name a write to `path` goes through: `.NAME.PID.tmp` in `path`'s folder (the
/// process id keeps two processes writing the same file apart).
pub fn temp_path(path: &Path) -> io::Result<PathBuf> {
    let name = path
        .file_name()
        .ok_or_else(|| io::Error::new(io::ErrorKind::InvalidInput, format!("{}: not a file name", path.display())))?;
    Ok(path.with_file_name(format!(".{}.{}.tmp", name.to_string_lossy(), std::process::id())))
}

/// Refuses a destination that exists and is not a regular file: a symbolic link, a folder, a
/// device, a FIFO or a socket. The rename of [`write_with`] would replace it by a regular file
/// (as root, `/dev/full` itself); zoo writes only regular files, so the user names one.
pub fn check_destination(path: &Path) -> io::Result<()> {
    let Ok(meta) = std::fs::symlink_metadata(path) else { return Ok(()) };
    let kind = meta.file_type();
    if kind.is_file() {
        return Ok(());
    }
    let what = if kind.is_symlink() {
        match std::fs::read_link(path) {
            Ok(to) => format!("a symbolic link (to {}); give the path of the file itself", to.display()),
            Err(_) => "a symbolic link; give the path of the file itself".to_string(),
        }
    } else if kind.is_dir() {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("{}: is a folder; give a file name", path.display()),
        ));
    } else {
        format!("{}; zoo writes only regular files: give a file name", special_kind(&kind))
    };
    Err(io::Error::new(
        io::ErrorKind::InvalidInput,
        format!("{}: exists and is not a regular file but {what} (it was left as it is)", path.display()),
    ))
}

#[cfg(unix)]
fn special_kind(kind: &std::fs::FileType) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    if kind.is_char_device() || kind.is_block_device() {
        "a device"
    } else if kind.is_fifo() {
        "a FIFO (named pipe)"
    } else if kind.is_socket() {
        "a socket"
    } else {
        "a special file"
    }
}

#[cfg(not(unix))]
fn special_kind(_: &std::fs::FileType) -> &'static str {
    "a special file"
}

/// Writes `path` atomically with `write`, which fills the temporary file (buffer it, or wrap
/// it in an encoder, as needed; the file is synced after `write` returns). A destination that
/// exists and is not a regular file is refused ([`check_destination`]).
pub fn write_with(path: &Path, write: impl FnOnce(&mut File) -> io::Result<()>) -> io::Result<()> {
    check_destination(path)?;
    let tmp = temp_path(path)?;
    let result = (|| {
        let mut file = File::create(&tmp)?;
        write(&mut file)?;
        file.sync_all()?;
        std::fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = std::fs::remove_file(&tmp);
    }
    result
}

/// Writes `bytes` to `path` atomically.
pub fn write(path: &Path, bytes: impl AsRef<[u8]>) -> io::Result<()> {
    use std::io::Write;
    write_with(path, |f| f.write_all(bytes.as_ref()))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_write_replaces_the_file_and_leaves_no_temporary_file() {
        let dir = std::env::temp_dir().join(format!("zoo-atomic-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("a.json");
        write(&path, "old").unwrap();
        write(&path, b"new").unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "new");
        // A failing writer leaves the old file and no temporary file.
        let err = write_with(&path, |_| Err(io::Error::other("disk full"))).unwrap_err();
        assert_eq!(err.to_string(), "disk full");
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "new");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1);
        assert!(write(&dir.join(".."), "x").is_err(), "not a file name");
        // A symbolic link, a folder and a device are refused and left as they are.
        #[cfg(unix)]
        {
            let link = dir.join("link.json");
            std::os::unix::fs::symlink(&path, &link).unwrap();
            let err = write(&link, "x").unwrap_err().to_string();
            assert!(err.contains("is not a regular file but a symbolic link"), "{err}");
            assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
            let err = write(Path::new("/dev/null"), "x").unwrap_err().to_string();
            assert!(err.contains("a device"), "{err}");
            std::fs::remove_file(&link).unwrap();
        }
        let sub = dir.join("sub");
        std::fs::create_dir(&sub).unwrap();
        assert!(write(&sub, "x").unwrap_err().to_string().contains("a folder"));
        std::fs::remove_dir(&sub).unwrap();
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
