//! The memory bound of reading: a file's bytes (unpacked, for `.bvh.gz`) are counted before they
//! are held, and a file past the bound is refused with its size, the bound and how to raise it.
//! The bound is 2 GB of memory by default (`ZOO_MEMORY_GB` raises or lowers it); a clip file may
//! hold a quarter of it, as parsing holds the text, its numbers and the clip at once.

use std::io::{self, Read};
use std::path::Path;

/// The memory bound in bytes: `ZOO_MEMORY_GB` (a number of GB in (0, 1e6]) or 2 GB.
pub fn memory_bound() -> u64 {
    std::env::var("ZOO_MEMORY_GB")
        .ok()
        .and_then(|v| v.trim().parse::<f64>().ok())
        .filter(|g| g.is_finite() && *g > 0.0 && *g <= 1e6)
        .map_or(2_000_000_000, |g| (g * 1e9) as u64)
}

/// The largest file (unpacked) a reader holds: a quarter of [`memory_bound`].
pub fn file_bound() -> u64 {
    memory_bound() / 4
}

fn too_large(path: &Path, what: &str, size: Option<u64>) -> io::Error {
    let bound = file_bound();
    let size =
        size.map_or_else(|| format!("more than {:.1} MB", bound as f64 / 1e6), |s| format!("{:.1} MB", s as f64 / 1e6));
    io::Error::new(
        io::ErrorKind::InvalidData,
        format!(
            "{}: {what} {size}, past the {:.1} MB a file may hold (a quarter of the memory bound of {:.2} GB); \
             raise the bound with the environment variable ZOO_MEMORY_GB=N if the machine holds it",
            path.display(),
            bound as f64 / 1e6,
            memory_bound() as f64 / 1e9
        ),
    )
}

/// Reads the regular file `path` whole, after checking its size against [`file_bound`]; a
/// device, FIFO or other special file is refused (reading `/dev/zero` never ends).
pub fn read_file(path: &Path) -> io::Result<Vec<u8>> {
    let mut file = std::fs::File::open(path)?;
    let meta = file.metadata()?;
    if !meta.is_file() {
        return Err(io::Error::new(
            io::ErrorKind::InvalidInput,
            format!("{}: not a regular file (a device, FIFO or folder); zoo reads files", path.display()),
        ));
    }
    if meta.len() > file_bound() {
        return Err(too_large(path, "is", Some(meta.len())));
    }
    let mut out = Vec::with_capacity(meta.len() as usize);
    file.by_ref().take(file_bound() + 1).read_to_end(&mut out)?;
    if out.len() as u64 > file_bound() {
        return Err(too_large(path, "is", None));
    }
    Ok(out)
}

/// The bytes `open()` gives, counted first without holding them: refused past [`file_bound`]
/// (a few MB of gzip can unpack to gigabytes), else read into a buffer of the counted size.
pub fn read_unpacked<R: Read>(path: &Path, open: impl Fn() -> R) -> io::Result<Vec<u8>> {
    let bound = file_bound();
    let n = io::copy(&mut open().take(bound + 1), &mut io::sink())?;
    if n > bound {
        return Err(too_large(path, "unpacks to", None));
    }
    let mut out = Vec::with_capacity(n as usize);
    open().take(n).read_to_end(&mut out)?;
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_device_is_refused_and_sizes_are_counted_before_they_are_held() {
        let e = read_file(Path::new("/dev/zero")).unwrap_err().to_string();
        assert!(e.contains("not a regular file"), "{e}");
        let zeros = || io::repeat(0);
        let e = read_unpacked(Path::new("x.bvh.gz"), zeros).unwrap_err().to_string();
        assert!(
            e.contains("x.bvh.gz: unpacks to more than 500.0 MB, past the 500.0 MB") && e.contains("ZOO_MEMORY_GB"),
            "{e}"
        );
        assert_eq!(read_unpacked(Path::new("x"), || &b"abc"[..]).unwrap(), b"abc");
    }
}
