//! BVH reader and writer.
//!
//! Reading accepts `.bvh` text and gzip-compressed `.bvh.gz` files (detected by their magic
//! bytes), 3 or 6 channels per joint in any order, tabs or spaces, CRLF line ends, `End Site`
//! blocks and any frame time. Rotation channels map to an [`EulerOrder`] in file order
//! (`Zrotation Xrotation Yrotation` is `q = qz * qx * qy`); angles are degrees. Position
//! channels become the joint's local translation; joints without them use their `OFFSET` in
//! every frame. Quaternions are normalized but their signs are left as the Euler conversion
//! gives them: callers that need continuity call [`Clip::remove_sign_flips`].
//!
//! The motion section must hold exactly the rows `Frames:` declares: fewer or more rows is an
//! error (never silently dropped motion). Blank lines between rows are skipped.
//!
//! Writing produces the standard layout (`HIERARCHY`, `ROOT`, `JOINT`, `End Site`, `MOTION`,
//! `Frames:`, `Frame Time:`) with tab indentation that Blender and MotionBuilder import.

use fast_float2::parse_partial;
use glam::{DQuat, DVec3};
use std::collections::HashSet;
use std::io::Write;
use std::path::{Path, PathBuf};
use zoo_motion::{Clip, EulerOrder, JointChannels, Skeleton};

/// Options for reading BVH.
#[derive(Clone, Debug, Default)]
pub struct ReadOptions {
    /// Drop a dummy root (a first joint with a single child, a zero offset and channels that
    /// are all zero in every frame, like bandai2's `joint_Root`), so its child becomes the root.
    pub drop_dummy_root: bool,
}

/// A BVH error: the file, the line (1-based, 0 when not tied to a line) and what was expected.
#[derive(Debug, thiserror::Error)]
pub enum BvhError {
    /// The file could not be read.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// File.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// The text is not valid BVH.
    #[error("{path}:{line}: {message}")]
    Parse {
        /// File.
        path: PathBuf,
        /// 1-based line number.
        line: usize,
        /// What was found and what was expected.
        message: String,
    },
}

/// The memory bound of reading: a file's bytes (unpacked, for `.bvh.gz`) are counted before they
/// are held, and a file past the bound is refused with its size, the bound and how to raise it.
/// The bound is 2 GB of memory by default (`ZOO_MEMORY_GB` raises or lowers it); a clip file may
/// hold a quarter of it, as parsing holds the text, its numbers and the clip at once.
/// (A module of this file, so that the Python binding, which compiles this file alone, reads
/// files the same way.)
pub mod limits {
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
        let size = size
            .map_or_else(|| format!("more than {:.1} MB", bound as f64 / 1e6), |s| format!("{:.1} MB", s as f64 / 1e6));
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
}

/// Reads a `.bvh` or `.bvh.gz` file (gzip detected by its magic bytes).
pub fn read_file(path: &Path, opts: &ReadOptions) -> Result<Clip, BvhError> {
    let io = |source| BvhError::Io { path: path.to_path_buf(), source };
    let raw = limits::read_file(path).map_err(io)?;
    if raw.starts_with(&[0x1f, 0x8b]) {
        let text = limits::read_unpacked(path, || flate2::read::MultiGzDecoder::new(&raw[..])).map_err(io)?;
        parse_bytes(&text, path, opts)
    } else {
        parse_bytes(&raw, path, opts)
    }
}

/// Reads a clip the way the models see it: the dummy root dropped
/// ([`ReadOptions::drop_dummy_root`]) and quaternion sign flips removed.
pub fn read_model_clip(path: &Path) -> Result<Clip, BvhError> {
    let mut clip = read_file(path, &ReadOptions { drop_dummy_root: true })?;
    clip.remove_sign_flips();
    Ok(clip)
}

/// Parses BVH text; `path` is only used in error messages.
pub fn parse(text: &str, path: &Path, opts: &ReadOptions) -> Result<Clip, BvhError> {
    parse_bytes(text.as_bytes(), path, opts)
}

/// Parses BVH bytes (ASCII/UTF-8 text); `path` is only used in error messages.
pub fn parse_bytes(bytes: &[u8], path: &Path, opts: &ReadOptions) -> Result<Clip, BvhError> {
    let bytes = bytes.strip_prefix(b"\xEF\xBB\xBF").unwrap_or(bytes);
    if bytes.contains(&b'\r') && !bytes.contains(&b'\n') {
        return Err(BvhError::Parse {
            path: path.to_path_buf(),
            line: 1,
            message: "the lines end in CR alone (classic Mac OS line endings), which zoo does not read: convert the \
                      file to LF or CRLF line endings"
                .into(),
        });
    }
    let mut p = Parser { b: bytes, pos: 0, line: 1, path };
    let h = p.hierarchy()?;
    let mut clip = p.motion(h)?;
    if opts.drop_dummy_root && clip.dummy_root {
        clip.clip.drop_root();
    }
    Ok(clip.clip)
}

/// How one joint's channels sit in a frame row.
#[derive(Clone, Copy, Debug)]
struct Layout {
    /// Column of the joint's first channel in a row.
    start: usize,
    /// Number of channels (3 or 6).
    count: usize,
    /// Column (relative to `start`) of the X, Y, Z position channels, if any.
    pos: Option<[usize; 3]>,
    /// Columns (relative to `start`) of the three rotation channels, in file order.
    rot: [usize; 3],
    /// Rotation order.
    order: EulerOrder,
}

/// The parsed `HIERARCHY` section.
struct Hierarchy {
    skeleton: Skeleton,
    layouts: Vec<Layout>,
    columns: usize,
}

struct Parsed {
    clip: Clip,
    /// The first joint qualifies as a dummy root (see [`ReadOptions::drop_dummy_root`]).
    dummy_root: bool,
}

struct Parser<'a> {
    b: &'a [u8],
    pos: usize,
    /// 1-based line of `pos`.
    line: usize,
    path: &'a Path,
}

/// A whitespace-separated token and the line it is on.
#[derive(Clone, Copy)]
struct Tok<'a> {
    text: &'a [u8],
    line: usize,
}

impl Tok<'_> {
    fn is(&self, s: &str) -> bool {
        self.text == s.as_bytes()
    }
    fn show(&self) -> String {
        let s = String::from_utf8_lossy(&self.text[..self.text.len().min(40)]);
        if self.text.len() > 40 { format!("`{s}...`") } else { format!("`{s}`") }
    }
}

fn show(t: Option<Tok>) -> String {
    t.map_or_else(|| "the end of the file".to_string(), |t| t.show())
}

impl<'a> Parser<'a> {
    fn err(&self, line: usize, message: impl Into<String>) -> BvhError {
        BvhError::Parse { path: self.path.to_path_buf(), line, message: message.into() }
    }

    /// Next token, skipping whitespace (and counting lines).
    fn next(&mut self) -> Option<Tok<'a>> {
        let b = self.b;
        while self.pos < b.len() && b[self.pos].is_ascii_whitespace() {
            if b[self.pos] == b'\n' {
                self.line += 1;
            }
            self.pos += 1;
        }
        if self.pos >= b.len() {
            return None;
        }
        let start = self.pos;
        while self.pos < b.len() && !b[self.pos].is_ascii_whitespace() {
            self.pos += 1;
        }
        Some(Tok { text: &b[start..self.pos], line: self.line })
    }

    /// Line for an error at the end of the file.
    fn eof_line(&self) -> usize {
        self.line
    }

    fn line_of(&self, t: Option<Tok>) -> usize {
        t.map_or(self.eof_line(), |t| t.line)
    }

    fn expect(&mut self, word: &str, context: &str) -> Result<Tok<'a>, BvhError> {
        let t = self.next();
        match t {
            Some(t) if t.is(word) => Ok(t),
            _ => Err(self.err(self.line_of(t), format!("expected `{word}` {context}, found {}", show(t)))),
        }
    }

    /// Next token as a finite number; `what` describes it for the error message.
    fn number(&mut self, what: impl FnOnce() -> String) -> Result<f64, BvhError> {
        let t = self.next();
        let v = t.and_then(|t| match parse_partial::<f64, _>(t.text) {
            Ok((v, n)) if n == t.text.len() && v.is_finite() => Some(v),
            _ => None,
        });
        v.ok_or_else(|| self.err(self.line_of(t), format!("expected {} (a number), found {}", what(), show(t))))
    }

    /// Three numbers: the X, Y and Z values of `what`.
    fn vec3(&mut self, what: impl Fn() -> String) -> Result<DVec3, BvhError> {
        Ok(DVec3::new(
            self.number(|| format!("the X value of {}", what()))?,
            self.number(|| format!("the Y value of {}", what()))?,
            self.number(|| format!("the Z value of {}", what()))?,
        ))
    }

    // One function: a single pass of the parser over the HIERARCHY tokens, the joint stack its
    // state; this file is also compiled alone into the Python package (runtime/python/src/bvh.rs).
    fn hierarchy(&mut self) -> Result<Hierarchy, BvhError> {
        let t = self.next();
        match t {
            None => return Err(self.err(1, "empty file: expected `HIERARCHY`")),
            Some(t) if t.is("HIERARCHY") => {}
            Some(_) => {
                return Err(self.err(self.line_of(t), format!("expected `HIERARCHY`, found {}", show(t))));
            }
        }
        self.expect("ROOT", "after HIERARCHY")?;
        let mut sk = Skeleton {
            names: Vec::new(),
            parents: Vec::new(),
            offsets: Vec::new(),
            end_sites: Vec::new(),
            channels: Vec::new(),
        };
        let mut layouts: Vec<Layout> = Vec::new();
        let mut names: HashSet<Vec<u8>> = HashSet::new();
        let mut columns = 0usize;
        // Stack of open joints: (joint index, line of its `{`).
        let mut stack: Vec<(usize, usize)> = Vec::new();
        let mut parent: Option<usize> = None;
        loop {
            // A joint header: the keyword (ROOT/JOINT) was consumed; name and `{` follow.
            let name_tok = self.next();
            let name_tok = match name_tok {
                Some(t) if !t.is("{") && !t.is("}") => t,
                _ => {
                    return Err(
                        self.err(self.line_of(name_tok), format!("expected a joint name, found {}", show(name_tok)))
                    );
                }
            };
            if !names.insert(name_tok.text.to_vec()) {
                return Err(self.err(
                    name_tok.line,
                    format!("duplicate joint name {}: expected unique joint names", name_tok.show()),
                ));
            }
            let name = String::from_utf8_lossy(name_tok.text).into_owned();
            let open = self.expect("{", &format!("after joint `{name}`"))?;
            let j = sk.names.len();
            if j >= Skeleton::MAX_JOINTS {
                return Err(self.err(
                    name_tok.line,
                    format!(
                        "joint `{name}` is joint {}; zoo reads at most {} joints (real skeletons have under 1000)",
                        j + 1,
                        Skeleton::MAX_JOINTS
                    ),
                ));
            }
            sk.names.push(name);
            sk.parents.push(parent);
            sk.offsets.push(DVec3::ZERO);
            sk.end_sites.push(None);
            sk.channels.push(JointChannels::default());
            layouts.push(Layout { start: columns, count: 0, pos: None, rot: [0, 1, 2], order: EulerOrder::Zxy });
            stack.push((j, open.line));
            if stack.len() > Skeleton::MAX_DEPTH + 1 {
                return Err(self.err(
                    open.line,
                    format!(
                        "joint `{}` is nested {} levels below the root; zoo reads at most {} levels (real skeletons \
                         have under 100)",
                        sk.names[j],
                        stack.len() - 1,
                        Skeleton::MAX_DEPTH
                    ),
                ));
            }
            let mut have_offset = false;
            // Body items of joint `j` until its `}` or a child joint.
            let mut descended = false;
            loop {
                let t = self.next();
                let Some(tok) = t else {
                    let (j, line) = *stack.last().expect("stack holds the current joint");
                    return Err(self.err(
                        self.eof_line(),
                        format!(
                            "unbalanced braces: expected `}}` closing joint `{}` (opened at line {line}), \
                             found the end of the file",
                            sk.names[j]
                        ),
                    ));
                };
                let cur = stack.last().expect("stack holds the current joint").0;
                if tok.is("OFFSET") {
                    sk.offsets[cur] = self.vec3(|| format!("the OFFSET of `{}`", sk.names[cur]))?;
                    have_offset = true;
                } else if tok.is("CHANNELS") {
                    if layouts[cur].count != 0 {
                        return Err(self.err(tok.line, format!("joint `{}` has a second CHANNELS line", sk.names[cur])));
                    }
                    let (lay, ch) = self.channels(tok.line, columns, &sk.names[cur])?;
                    columns += lay.count;
                    layouts[cur] = lay;
                    sk.channels[cur] = ch;
                } else if tok.is("JOINT") {
                    self.check_joint(&sk, &layouts, cur, have_offset, tok.line)?;
                    parent = Some(cur);
                    descended = true;
                    break;
                } else if tok.is("End") {
                    self.expect("Site", "after `End`")?;
                    self.expect("{", "after `End Site`")?;
                    self.expect("OFFSET", "in `End Site`")?;
                    let o = self.vec3(|| format!("the End Site OFFSET of `{}`", sk.names[cur]))?;
                    sk.end_sites[cur] = Some(o);
                    self.expect("}", "closing `End Site`")?;
                } else if tok.is("}") {
                    self.check_joint(&sk, &layouts, cur, have_offset, tok.line)?;
                    stack.pop();
                    // Continue in the parent's body: siblings or its closing brace.
                    if stack.is_empty() {
                        break;
                    }
                    have_offset = true; // the parent was checked when its first child opened
                } else if tok.is("MOTION") || tok.is("ROOT") {
                    let (j, line) = *stack.last().expect("stack holds the current joint");
                    return Err(self.err(
                        tok.line,
                        format!(
                            "unbalanced braces: expected `}}` closing joint `{}` (opened at line {line}), found {}",
                            sk.names[j],
                            tok.show()
                        ),
                    ));
                } else {
                    return Err(self.err(
                        tok.line,
                        format!(
                            "expected OFFSET, CHANNELS, JOINT, End Site or `}}` in joint `{}`, found {}",
                            sk.names[cur],
                            tok.show()
                        ),
                    ));
                }
            }
            if !descended {
                break;
            }
        }
        Ok(Hierarchy { skeleton: sk, layouts, columns })
    }

    fn check_joint(
        &self,
        sk: &Skeleton,
        layouts: &[Layout],
        j: usize,
        have_offset: bool,
        line: usize,
    ) -> Result<(), BvhError> {
        if !have_offset {
            return Err(self.err(line, format!("expected an OFFSET line in joint `{}`", sk.names[j])));
        }
        if layouts[j].count == 0 {
            return Err(self.err(line, format!("expected a CHANNELS line in joint `{}`", sk.names[j])));
        }
        Ok(())
    }

    /// Parses `n name...` after `CHANNELS`.
    fn channels(&mut self, line: usize, start: usize, joint: &str) -> Result<(Layout, JointChannels), BvhError> {
        let t = self.next();
        let count = match t.map(|t| t.text) {
            Some(b"3") => 3,
            Some(b"6") => 6,
            _ => {
                return Err(self.err(
                    self.line_of(t).max(line),
                    format!("expected a CHANNELS count of 3 or 6 in joint `{joint}`, found {}", show(t)),
                ));
            }
        };
        let mut pos: [Option<usize>; 3] = [None; 3];
        let mut rot: Vec<(usize, usize)> = Vec::with_capacity(3); // (axis, column)
        for c in 0..count {
            let t = self.next();
            let parsed = t.and_then(|t| {
                let s = t.text;
                if s.len() != 9 {
                    return None;
                }
                let axis = match s[0].to_ascii_uppercase() {
                    b'X' => 0,
                    b'Y' => 1,
                    b'Z' => 2,
                    _ => return None,
                };
                let kind = s[1..].to_ascii_lowercase();
                match kind.as_slice() {
                    b"position" => Some((axis, true)),
                    b"rotation" => Some((axis, false)),
                    _ => None,
                }
            });
            let Some((axis, is_pos)) = parsed else {
                return Err(self.err(
                    self.line_of(t),
                    format!(
                        "unknown channel {} in joint `{joint}`: expected Xposition, Yposition, Zposition, \
                         Xrotation, Yrotation or Zrotation",
                        show(t)
                    ),
                ));
            };
            let line = self.line_of(t);
            if is_pos {
                if pos[axis].is_some() {
                    return Err(self.err(line, format!("repeated position channel in joint `{joint}`")));
                }
                pos[axis] = Some(c);
            } else {
                if rot.iter().any(|&(a, _)| a == axis) {
                    return Err(self.err(
                        line,
                        format!(
                            "rotation order with a repeated axis in joint `{joint}`: expected each of \
                             Xrotation, Yrotation, Zrotation once"
                        ),
                    ));
                }
                rot.push((axis, c));
            }
        }
        let n_pos = pos.iter().filter(|p| p.is_some()).count();
        if rot.len() != 3 || (n_pos != 0 && n_pos != 3) {
            return Err(self.err(
                line,
                format!(
                    "expected three rotation channels (and optionally three position channels) in joint \
                     `{joint}`, found {} rotation and {n_pos} position channels",
                    rot.len()
                ),
            ));
        }
        let order = EulerOrder::from_axes([rot[0].0, rot[1].0, rot[2].0])
            .ok_or_else(|| self.err(line, format!("rotation order with a repeated axis in joint `{joint}`")))?;
        let pos = if n_pos == 3 { Some(pos.map(|p| p.unwrap_or(0))) } else { None };
        let layout = Layout { start, count, pos, rot: [rot[0].1, rot[1].1, rot[2].1], order };
        Ok((layout, JointChannels { position: pos.is_some(), order }))
    }

    fn motion(&mut self, h: Hierarchy) -> Result<Parsed, BvhError> {
        let t = self.next();
        match t {
            Some(t) if t.is("MOTION") => {}
            Some(t) if t.is("}") => {
                return Err(
                    self.err(t.line, "unbalanced braces: found `}` after the ROOT joint closed, expected `MOTION`")
                );
            }
            _ => {
                return Err(
                    self.err(self.line_of(t), format!("expected `MOTION` after the hierarchy, found {}", show(t)))
                );
            }
        }
        let t = self.next();
        if !t.is_some_and(|t| t.is("Frames:")) {
            return Err(self.err(self.line_of(t), format!("expected `Frames:` after MOTION, found {}", show(t))));
        }
        let t = self.next();
        let frames: usize = match t.and_then(|t| std::str::from_utf8(t.text).ok()?.parse().ok()) {
            Some(n) => n,
            None => {
                return Err(self.err(
                    self.line_of(t),
                    format!("expected the frame count (a non-negative integer) after `Frames:`, found {}", show(t)),
                ));
            }
        };
        let t = self.next();
        let ok = t.is_some_and(|t| t.is("Frame")) && {
            let t2 = self.next();
            t2.is_some_and(|t2| t2.is("Time:"))
        };
        if !ok {
            return Err(
                self.err(self.line_of(t), format!("expected `Frame Time:` after the frame count, found {}", show(t)))
            );
        }
        let t = self.next();
        let frame_time = t
            .and_then(|t| match parse_partial::<f64, _>(t.text) {
                Ok((v, n)) if n == t.text.len() && v.is_finite() && v > 0.0 => Some(v),
                _ => None,
            })
            .ok_or_else(|| {
                self.err(
                    self.line_of(t),
                    format!("expected the frame time (a positive number of seconds), found {}", show(t)),
                )
            })?;
        Clip::check_frame_time(frame_time).map_err(|e| self.err(self.line_of(t), format!("`Frame Time:` {e}")))?;
        // Rest of the `Frame Time:` line must be empty.
        self.skip_blank();
        if self.pos < self.b.len() && self.b[self.pos] != b'\n' {
            let t = self.next();
            return Err(
                self.err(self.line_of(t), format!("expected the end of the `Frame Time:` line, found {}", show(t)))
            );
        }
        self.frames(h, frames, frame_time)
    }

    /// Skips the whitespace of a line: every ASCII whitespace but the line feed (spaces, tabs,
    /// carriage returns, form feeds), the same set that separates tokens.
    #[inline]
    fn skip_blank(&mut self) {
        while self.pos < self.b.len() && matches!(self.b[self.pos], b' ' | b'\t' | b'\r' | b'\x0c') {
            self.pos += 1;
        }
    }

    /// Reads `frames` rows of `h.columns` numbers each. `pos` is at the end of the
    /// `Frame Time:` line.
    // One function: the hot loop of the reader (one pass over the MOTION numbers, the fast path
    // and its error reporting side by side, measured in examples/bvh_read_bench.rs).
    fn frames(&mut self, h: Hierarchy, frames: usize, frame_time: f64) -> Result<Parsed, BvhError> {
        let Hierarchy { skeleton, layouts, columns } = h;
        let nj = skeleton.len();
        let b = self.b;
        // Pre-size from `Frames:`, bounded by what the remaining bytes can hold (each value
        // takes at least two bytes) so a forged count cannot request a huge allocation.
        let cap = frames.min((b.len() - self.pos) / (2 * columns) + 1);
        let mut rotations: Vec<DQuat> = Vec::with_capacity(cap * nj);
        let mut positions: Vec<DVec3> = Vec::with_capacity(cap * nj);
        let mut row = vec![0.0f64; columns];
        let root_cols = layouts[0].count;
        let mut root_nonzero = skeleton.offsets[0] != DVec3::ZERO;
        let mut f = 0;
        while f < frames {
            // Move to the start of the next non-blank line.
            self.skip_blank();
            if self.pos < b.len() && b[self.pos] == b'\n' {
                self.pos += 1;
                self.line += 1;
                continue;
            }
            if self.pos >= b.len() {
                return Err(self
                    .err(self.line, format!("expected {frames} frame rows as declared by `Frames:`, found only {f}")));
            }
            let line = self.line;
            let mut c = 0;
            loop {
                self.skip_blank();
                if self.pos >= b.len() || b[self.pos] == b'\n' {
                    break;
                }
                let rest = &b[self.pos..];
                let parsed = match parse_partial::<f64, _>(rest) {
                    Ok((v, n)) if v.is_finite() && (n == rest.len() || rest[n].is_ascii_whitespace()) => Some((v, n)),
                    _ => None,
                };
                let Some((v, n)) = parsed else {
                    let end = rest.iter().position(|x| x.is_ascii_whitespace()).unwrap_or(rest.len());
                    let tok = Tok { text: &rest[..end], line };
                    return Err(self.err(
                        line,
                        format!(
                            "expected a number (value {} of {columns} in frame {}), found {}",
                            c + 1,
                            f + 1,
                            tok.show()
                        ),
                    ));
                };
                if c < columns {
                    row[c] = v;
                }
                c += 1;
                self.pos += n;
            }
            if c != columns {
                return Err(self.err(
                    line,
                    format!(
                        "expected {columns} values in frame {} (the channel count of the hierarchy), found {c}",
                        f + 1
                    ),
                ));
            }
            root_nonzero |= row[..root_cols].iter().any(|&v| v != 0.0);
            for (j, l) in layouts.iter().enumerate() {
                let v = &row[l.start..l.start + l.count];
                let q = l.order.to_quat_deg([v[l.rot[0]], v[l.rot[1]], v[l.rot[2]]]).normalize();
                rotations.push(q);
                positions.push(match l.pos {
                    Some(p) => DVec3::new(v[p[0]], v[p[1]], v[p[2]]),
                    None => skeleton.offsets[j],
                });
            }
            f += 1;
        }
        // Rows beyond the declared count: an error, not silently dropped motion.
        loop {
            self.skip_blank();
            if self.pos < b.len() && b[self.pos] == b'\n' {
                self.pos += 1;
                self.line += 1;
                continue;
            }
            break;
        }
        if self.pos < b.len() {
            let extra =
                b[self.pos..].split(|&c| c == b'\n').filter(|l| l.iter().any(|c| !c.is_ascii_whitespace())).count();
            return Err(self.err(
                self.line,
                format!(
                    "{extra} more frame row(s) than the {frames} declared by `Frames:`; set `Frames: {}` if they \
                     belong to the clip, or delete them",
                    frames + extra
                ),
            ));
        }
        let dummy_root = !root_nonzero && skeleton.children(0).len() == 1;
        Ok(Parsed {
            clip: Clip { skeleton, frame_time, local_rotations: rotations, local_positions: positions },
            dummy_root,
        })
    }
}

/// Writes a clip as BVH text.
///
/// Joints are written in depth-first order from the root (the skeleton's own order for
/// skeletons read from BVH). A joint gets `Xposition Yposition Zposition` channels when its
/// [`JointChannels::position`] is set or when its translation differs from its offset in some
/// frame (so root motion is never lost), followed by its rotation channels in its own order.
/// Whitespace in joint names becomes `_` (BVH names are single tokens).
/// Offsets and the frame time are written with shortest round-trip precision, motion values
/// with 6 decimals (error <= 5e-7 degrees / clip units).
pub fn to_string(clip: &Clip) -> String {
    let sk = &clip.skeleton;
    let nj = sk.len();
    let frames = clip.frames();
    let mut out = String::with_capacity(1024 + frames * nj * 6 * 12);
    if nj == 0 {
        return out;
    }
    let mut children: Vec<Vec<usize>> = vec![Vec::new(); nj];
    for j in 0..nj {
        if let Some(p) = sk.parents[j] {
            children[p].push(j);
        }
    }
    let with_pos: Vec<bool> = (0..nj)
        .map(|j| {
            sk.channels[j].position
                || (0..frames).any(|f| (clip.local_positions[f * nj + j] - sk.offsets[j]).abs().max_element() > 1e-9)
        })
        .collect();
    let mut order = Vec::with_capacity(nj);
    out.push_str("HIERARCHY\n");
    write_joint(&mut out, sk, &children, &with_pos, 0, 0, &mut order);
    use std::fmt::Write as _;
    let _ = write!(out, "MOTION\nFrames: {frames}\nFrame Time: {}\n", clip.frame_time);
    for f in 0..frames {
        let mut first = true;
        let mut num = |out: &mut String, v: f64| {
            if !first {
                out.push(' ');
            }
            first = false;
            let v = if v == 0.0 { 0.0 } else { v }; // no "-0.000000"
            let _ = write!(out, "{v:.6}");
        };
        for &j in &order {
            if with_pos[j] {
                let p = clip.local_positions[f * nj + j];
                for v in [p.x, p.y, p.z] {
                    num(&mut out, v);
                }
            }
            let e = sk.channels[j].order.from_quat_deg(clip.local_rotations[f * nj + j]);
            for v in e {
                num(&mut out, v);
            }
        }
        out.push('\n');
    }
    out
}

/// Writes the hierarchy below joint `j` (depth first, children in index order; `order` gets
/// the joints in the order their channels are written). A stack, not recursion: a skeleton can
/// be as deep as its source made it.
fn write_joint(
    out: &mut String,
    sk: &Skeleton,
    children: &[Vec<usize>],
    with_pos: &[bool],
    j: usize,
    depth: usize,
    order: &mut Vec<usize>,
) {
    use std::fmt::Write as _;
    // (joint, depth, opening: false when only its End Site and closing brace are left).
    let mut stack = vec![(j, depth, true)];
    while let Some((j, depth, opening)) = stack.pop() {
        let ind = "\t".repeat(depth);
        if !opening {
            if let Some(e) = sk.end_sites[j] {
                let _ = writeln!(out, "{ind}\tEnd Site\n{ind}\t{{\n{ind}\t\tOFFSET {} {} {}\n{ind}\t}}", e.x, e.y, e.z);
            }
            let _ = writeln!(out, "{ind}}}");
            continue;
        }
        order.push(j);
        let kw = if depth == 0 { "ROOT" } else { "JOINT" };
        let o = sk.offsets[j];
        let _ = writeln!(out, "{ind}{kw} {}\n{ind}{{\n{ind}\tOFFSET {} {} {}", joint_name(&sk.names[j]), o.x, o.y, o.z);
        let axes = sk.channels[j].order.axes().map(|a| ["Xrotation", "Yrotation", "Zrotation"][a]);
        let rot = axes.join(" ");
        if with_pos[j] {
            let _ = writeln!(out, "{ind}\tCHANNELS 6 Xposition Yposition Zposition {rot}");
        } else {
            let _ = writeln!(out, "{ind}\tCHANNELS 3 {rot}");
        }
        stack.push((j, depth, false));
        stack.extend(children[j].iter().rev().map(|&c| (c, depth + 1, true)));
    }
}

/// A joint name as one BVH token: whitespace becomes `_`, an empty name `_`.
fn joint_name(name: &str) -> String {
    if name.is_empty() {
        return "_".into();
    }
    name.chars().map(|c| if c.is_whitespace() { '_' } else { c }).collect()
}

/// Writes a clip to a `.bvh` file (or gzip-compressed when the name ends in `.gz`).
///
/// The file is written to a temporary file in the same folder and renamed into place, so a
/// reader never sees a half-written file.
/// A clip holding NaN or infinity is refused ([`zoo_motion::finite::check_clip`]).
pub fn write_file(clip: &Clip, path: &Path) -> std::io::Result<()> {
    zoo_motion::finite::check_clip(&path.display().to_string(), clip)?;
    let text = to_string(clip);
    let gz = path.file_name().is_some_and(|n| n.to_string_lossy().ends_with(".gz"));
    zoo_format::atomic::write_with(path, |file| {
        let mut w = std::io::BufWriter::new(file);
        if gz {
            let mut enc = flate2::write::GzEncoder::new(w, flate2::Compression::default());
            enc.write_all(text.as_bytes())?;
            w = enc.finish()?;
        } else {
            w.write_all(text.as_bytes())?;
        }
        w.flush()
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A valid file: line numbers in the tests below refer to it.
    const VALID: &str = "HIERARCHY
ROOT Hips
{
\tOFFSET 0 90 0
\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
\tJOINT Leg
\t{
\t\tOFFSET 10 -40 0
\t\tCHANNELS 3 Zrotation Xrotation Yrotation
\t\tEnd Site
\t\t{
\t\t\tOFFSET 0 -40 0
\t\t}
\t}
}
MOTION
Frames: 2
Frame Time: 0.0333333
1 90 2 10 20 30 -5 0 45
1.5 90.5 2.5 11 21 31 -6 1 44
";

    fn read(text: &str) -> Result<Clip, BvhError> {
        parse(text, Path::new("case.bvh"), &ReadOptions::default())
    }

    /// Parses `text`, which must fail on `line` with a message containing `expected`.
    fn assert_fails(text: &str, line: usize, expected: &str) {
        let err = read(text).expect_err("malformed input must be rejected");
        let shown = err.to_string();
        assert!(shown.starts_with(&format!("case.bvh:{line}: ")), "wrong file/line in `{shown}`");
        assert!(shown.contains(expected), "`{shown}` does not say `{expected}`");
        match err {
            BvhError::Parse { line: l, .. } => assert_eq!(l, line),
            other => panic!("expected a parse error, got {other:?}"),
        }
    }

    #[test]
    fn valid_file_parses() {
        let clip = read(VALID).unwrap();
        assert_eq!(clip.frames(), 2);
        assert_eq!(clip.joints(), 2);
    }

    #[test]
    fn malformed_empty_file() {
        assert_fails("", 1, "empty file: expected `HIERARCHY`");
        assert_fails(" \r\n\t\n", 1, "empty file: expected `HIERARCHY`");
    }

    #[test]
    fn malformed_missing_hierarchy_keyword() {
        assert_fails(&VALID.replacen("HIERARCHY", "HIERARCH", 1), 1, "expected `HIERARCHY`");
    }

    #[test]
    fn malformed_missing_motion() {
        let text = VALID.replace("MOTION\n", "");
        assert_fails(&text, 16, "expected `MOTION`");
    }

    #[test]
    fn malformed_truncated_before_motion() {
        let text = &VALID[..VALID.find("MOTION").unwrap()];
        assert_fails(text, 16, "expected `MOTION` after the hierarchy, found the end of the file");
    }

    #[test]
    fn malformed_missing_frames() {
        let text = VALID.replace("Frames: 2\n", "");
        assert_fails(&text, 17, "expected `Frames:` after MOTION");
    }

    #[test]
    fn malformed_bad_frame_count() {
        assert_fails(&VALID.replace("Frames: 2", "Frames: two"), 17, "expected the frame count");
        assert_fails(&VALID.replace("Frames: 2", "Frames: -2"), 17, "expected the frame count");
    }

    #[test]
    fn malformed_missing_frame_time() {
        let text = VALID.replace("Frame Time: 0.0333333\n", "");
        assert_fails(&text, 18, "expected `Frame Time:`");
    }

    #[test]
    fn malformed_bad_frame_time() {
        assert_fails(&VALID.replace("0.0333333", "0"), 18, "expected the frame time (a positive number");
        assert_fails(&VALID.replace("0.0333333", "fast"), 18, "expected the frame time");
    }

    #[test]
    fn frame_times_outside_the_range_are_refused() {
        for t in ["1e-30", "1e30", "0.00001", "11"] {
            assert_fails(&VALID.replace("0.0333333", t), 18, "is outside the valid range [0.0001, 10] s");
        }
        assert!(read(&VALID.replace("0.0333333", "0.0001")).is_ok());
    }

    /// A chain of `n` joints, one frame.
    fn chain(n: usize) -> String {
        let mut t = String::from("HIERARCHY\n");
        for i in 0..n {
            let kw = if i == 0 { "ROOT" } else { "JOINT" };
            t += &format!("{kw} J{i}\n{{\nOFFSET 0 1 0\nCHANNELS 3 Zrotation Xrotation Yrotation\n");
        }
        t += &"}\n".repeat(n);
        t + &format!("MOTION\nFrames: 1\nFrame Time: 0.033\n{}\n", vec!["0"; 3 * n].join(" "))
    }

    #[test]
    fn a_hierarchy_deeper_than_the_limit_is_refused_at_parse_time() {
        let deepest = read(&chain(Skeleton::MAX_DEPTH + 1)).unwrap();
        assert_eq!(deepest.skeleton.depth(), Skeleton::MAX_DEPTH);
        // Written without recursion and read back the same.
        let again = read(&to_string(&deepest)).unwrap();
        assert_eq!(again.skeleton.parents, deepest.skeleton.parents);
        let e = read(&chain(Skeleton::MAX_DEPTH + 2)).unwrap_err().to_string();
        assert!(e.contains("joint `J1001` is nested 1001 levels below the root; zoo reads at most 1000"), "{e}");
        // 100,000 levels stop at the limit too (this overflowed the stack before).
        assert!(read(&chain(100_000)).is_err());
    }

    #[test]
    fn malformed_row_with_too_few_values() {
        let text = VALID.replace("1.5 90.5 2.5 11 21 31 -6 1 44", "1.5 90.5 2.5 11 21 31 -6 1");
        assert_fails(&text, 20, "expected 9 values in frame 2");
    }

    #[test]
    fn malformed_row_with_too_many_values() {
        let text = VALID.replace("-5 0 45", "-5 0 45 7");
        assert_fails(&text, 19, "expected 9 values in frame 1");
    }

    #[test]
    fn malformed_non_number() {
        let text = VALID.replace("11 21 31", "11 abc 31");
        assert_fails(&text, 20, "expected a number (value 5 of 9 in frame 2), found `abc`");
        let text = VALID.replace("11 21 31", "11 21x 31");
        assert_fails(&text, 20, "expected a number (value 5 of 9 in frame 2), found `21x`");
        let text = VALID.replace("11 21 31", "11 nan 31");
        assert_fails(&text, 20, "expected a number");
    }

    #[test]
    fn malformed_non_number_offset() {
        let text = VALID.replace("OFFSET 10 -40 0", "OFFSET 10 - 0");
        assert_fails(&text, 8, "expected the Y value of the OFFSET of `Leg` (a number), found `-`");
    }

    #[test]
    fn malformed_unknown_channel() {
        let text =
            VALID.replace("CHANNELS 3 Zrotation Xrotation Yrotation", "CHANNELS 3 Zrotation Wrotation Yrotation");
        assert_fails(&text, 9, "unknown channel `Wrotation` in joint `Leg`: expected Xposition");
    }

    #[test]
    fn malformed_fewer_rows_than_declared() {
        let text = VALID.replace("Frames: 2", "Frames: 3");
        assert_fails(&text, 21, "expected 3 frame rows as declared by `Frames:`, found only 2");
    }

    #[test]
    fn malformed_more_rows_than_declared() {
        assert_fails(
            &VALID.replace("Frames: 2", "Frames: 1"),
            20,
            "1 more frame row(s) than the 1 declared by `Frames:`",
        );
        assert_fails(
            &VALID.replace("Frames: 2", "Frames: 0"),
            19,
            "2 more frame row(s) than the 0 declared by `Frames:`; set `Frames: 2`",
        );
        // Trailing blank lines and spaces are not rows.
        assert_eq!(read(&format!("{VALID}\n  \r\n\n")).unwrap().frames(), 2);
    }

    #[test]
    fn malformed_unbalanced_braces_missing_close() {
        // Drop the `}` closing `Leg` (line 14).
        let text = VALID.replacen("\t}\n}\nMOTION", "}\nMOTION", 1);
        assert_fails(&text, 15, "unbalanced braces: expected `}` closing joint `Hips` (opened at line 3)");
    }

    #[test]
    fn malformed_unbalanced_braces_extra_close() {
        let text = VALID.replacen("}\nMOTION", "}\n}\nMOTION", 1);
        assert_fails(&text, 16, "unbalanced braces");
        assert_fails(&text, 16, "expected `MOTION`");
    }

    #[test]
    fn malformed_unbalanced_braces_at_end_of_file() {
        let text = &VALID[..VALID.find("\t}\n}").unwrap()];
        assert_fails(text, 14, "unbalanced braces: expected `}` closing joint `Leg` (opened at line 7)");
    }

    #[test]
    fn malformed_bad_channels_count() {
        let text = VALID.replace("CHANNELS 3 Zrotation", "CHANNELS 4 Zrotation");
        assert_fails(&text, 9, "expected a CHANNELS count of 3 or 6 in joint `Leg`, found `4`");
    }

    #[test]
    fn malformed_channels_without_rotations() {
        let text =
            VALID.replace("CHANNELS 3 Zrotation Xrotation Yrotation", "CHANNELS 3 Xposition Yposition Zposition");
        assert_fails(&text, 9, "expected three rotation channels");
    }

    #[test]
    fn malformed_duplicate_joint_names() {
        let text = VALID.replace("JOINT Leg", "JOINT Hips");
        assert_fails(&text, 6, "duplicate joint name `Hips`: expected unique joint names");
    }

    #[test]
    fn malformed_rotation_order_with_repeated_axis() {
        let text =
            VALID.replace("CHANNELS 3 Zrotation Xrotation Yrotation", "CHANNELS 3 Zrotation Xrotation Zrotation");
        assert_fails(&text, 9, "rotation order with a repeated axis in joint `Leg`: expected each of");
    }

    #[test]
    fn malformed_missing_offset() {
        let text = VALID.replace("\t\tOFFSET 10 -40 0\n", "");
        assert_fails(&text, 13, "expected an OFFSET line in joint `Leg`");
    }

    #[test]
    fn malformed_missing_channels() {
        let text = VALID.replace("\t\tCHANNELS 3 Zrotation Xrotation Yrotation\n", "");
        assert_fails(&text, 13, "expected a CHANNELS line in joint `Leg`");
    }

    #[test]
    fn malformed_unknown_keyword_in_joint() {
        let text = VALID.replace("\t\tEnd Site", "\t\tEndSite");
        assert_fails(&text, 10, "expected OFFSET, CHANNELS, JOINT, End Site or `}` in joint `Leg`, found `EndSite`");
    }

    /// Values without a leading digit, with a sign or an exponent are the numbers they spell.
    #[test]
    fn frame_values_without_a_leading_digit_with_signs_and_exponents() {
        let plain = read(VALID).unwrap();
        let spelled = VALID
            .replace("1 90 2 10 20 30 -5 0 45", "+1 9e1 2.0 1E1 +.2e2 30. -.5e1 -0 4.5e+1")
            .replace("1.5 90.5 2.5 11 21 31 -6 1 44", ".15e1 +90.5 2.5E0 11 21 31 -6e0 1. 440e-1");
        let c = read(&spelled).unwrap();
        assert_eq!(c.local_positions, plain.local_positions);
        assert_eq!(c.local_rotations, plain.local_rotations);
        let c = read(&VALID.replace("1 90 2 10", "-.5 .25 +.75 10")).unwrap();
        assert_eq!(c.local_positions[0], DVec3::new(-0.5, 0.25, 0.75));
    }

    /// Rows of such values beyond the declared count are counted as rows, whatever their first
    /// character; blank lines (spaces, tabs, CR, form feeds) are not rows.
    #[test]
    fn extra_rows_starting_with_a_dot_sign_or_exponent_are_counted() {
        let text = VALID.replace("Frames: 2", "Frames: 1")
            + "\t.5 -.5 +1 1e1 -1E-1 .0 0. -0 +.5\r\n\r\n-.5 0 0 0 0 0 0 0 0\n\x0c\n+1e0 0 0 0 0 0 0 0 0";
        assert_fails(&text, 20, "4 more frame row(s) than the 1 declared by `Frames:`; set `Frames: 5`");
        assert_eq!(read(&format!("{VALID}\x0c\n \x0c\r\n\t")).unwrap().frames(), 2);
        let text = VALID.replace("1 90 2 10", "\x0c1 90 2 10");
        assert_eq!(read(&text).unwrap().frames(), 2);
    }

    /// Malformed numbers are refused with the value as written.
    #[test]
    fn malformed_number_forms() {
        for bad in ["1e", "--1", "+-1", "1.2.3", "1,5", ".", "e5", "0x10", "1e400", "-inf", "+", "1e+", "1d5"] {
            let text = VALID.replace("11 21 31", &format!("11 {bad} 31"));
            assert_fails(&text, 20, &format!("expected a number (value 5 of 9 in frame 2), found `{bad}`"));
        }
    }

    #[test]
    fn huge_declared_frame_count_does_not_allocate_it() {
        let text = VALID.replace("Frames: 2", "Frames: 18446744073709551615");
        assert_fails(&text, 21, "expected 18446744073709551615 frame rows");
    }
}
