//! The one check of a command's paths before any work: no output is one of the command's
//! inputs (the same file after resolving links, hard links included) or another of its
//! outputs, no output replaces a file of a run folder the command reads, no clip file or output
//! folder lands inside a dataset folder it reads, and no output exists as something other than a regular file
//! (a symbolic link, a folder given for a file, a device, a FIFO). The paths of every
//! command are listed in one place, `main.rs`'s `io_of`.

use anyhow::bail;
use std::path::{Path, PathBuf};

/// The paths of one command line, by role, each with the option that gave it.
#[derive(Default)]
pub struct Io {
    /// Files read (clips, keys, scripts, paths, rig maps, exported models).
    inputs: Vec<(String, PathBuf)>,
    /// Run folders read: their files (`*.json`, `*.safetensors`) are inputs.
    runs: Vec<(String, PathBuf)>,
    /// Dataset files or folders read: no output inside.
    data: Vec<(String, PathBuf)>,
    /// Files written.
    outputs: Vec<(String, PathBuf)>,
    /// Folders written into.
    output_dirs: Vec<(String, PathBuf)>,
}

impl Io {
    /// A file read.
    pub fn input(mut self, option: &str, path: Option<&Path>) -> Self {
        if let Some(p) = path {
            self.inputs.push((option.to_string(), p.to_path_buf()));
        }
        self
    }

    /// A clip given as `FILE:FRAME` or `FILE[:FROM:TO]`: the file part is an input.
    pub fn clip_spec(self, option: &str, spec: Option<&str>) -> Self {
        let path = spec.map(clip_file_of);
        self.input(option, path.as_deref())
    }

    /// A model: a run folder, or an exported file.
    pub fn model(mut self, option: &str, path: Option<&Path>) -> Self {
        if let Some(p) = path {
            if p.is_dir() {
                self.runs.push((option.to_string(), p.to_path_buf()));
            } else {
                self.inputs.push((option.to_string(), p.to_path_buf()));
            }
        }
        self
    }

    /// A dataset: a clip file or a folder of clips.
    pub fn data(mut self, option: &str, path: Option<&Path>) -> Self {
        if let Some(p) = path {
            if p.is_dir() {
                self.data.push((option.to_string(), p.to_path_buf()));
            } else {
                self.inputs.push((option.to_string(), p.to_path_buf()));
            }
        }
        self
    }

    /// A file written.
    pub fn output(mut self, option: &str, path: Option<&Path>) -> Self {
        if let Some(p) = path {
            self.outputs.push((option.to_string(), p.to_path_buf()));
        }
        self
    }

    /// A BVH written with its contact labels beside it (`NAME.contacts.json`).
    pub fn output_with_contacts(self, option: &str, path: &Path) -> Self {
        let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        let contacts = path.with_file_name(format!("{stem}.contacts.json"));
        self.output(option, Some(path)).output(&format!("{option} (its contact labels)"), Some(&contacts))
    }

    /// A folder written into.
    pub fn output_dir(mut self, option: &str, path: Option<&Path>) -> Self {
        if let Some(p) = path {
            self.output_dirs.push((option.to_string(), p.to_path_buf()));
        }
        self
    }

    /// Checks the rules of this module; the first broken one is the error, naming both options
    /// and the fix.
    pub fn check(&self) -> anyhow::Result<()> {
        // A run folder whose old run an interrupted `--overwrite` kept aside is put back (under
        // the folder's lock, as a training does) before it is read; a running training's folder
        // is left to it.
        for (_, run) in &self.runs {
            if run.join(zoo_nn::run_folder::ASIDE_DIR).is_dir() {
                let _ = zoo_nn::run_folder::lock(run);
            }
        }
        for (option, out) in &self.outputs {
            if out.as_os_str() == "-" {
                continue;
            }
            zoo_format::atomic::check_destination(out).map_err(|e| anyhow::anyhow!("{option} {e}"))?;
            let key = Key::of(out);
            for (in_option, input) in &self.inputs {
                if key.same(&Key::of(input)) {
                    bail!(
                        "{option} {} is the input of {in_option} ({}): writing it would destroy the input; give another \
                         output path",
                        out.display(),
                        input.display()
                    );
                }
            }
            for (run_option, run) in &self.runs {
                if let Some(file) = run_file(run, out) {
                    bail!(
                        "{option} {} is the file {} of the run folder {run_option} {} that this command reads: writing \
                         it would destroy the run; give a path outside the run's files",
                        out.display(),
                        file,
                        run.display()
                    );
                }
            }
        }
        for (i, (option, out)) in self.outputs.iter().enumerate() {
            for (other_option, other) in &self.outputs[i + 1..] {
                if Key::of(out).same(&Key::of(other)) {
                    bail!(
                        "{option} {} and {other_option} {} are the same file: one would be lost; give each output its \
                         own path",
                        out.display(),
                        other.display()
                    );
                }
            }
        }
        // A clip file or a folder (which receives clips) would join a dataset it lands in; a
        // report (JSON, PNG) beside the clips is not read as a clip.
        let is_clip = |p: &PathBuf| zoo_data::clip_io::ClipFormat::of(p).is_some();
        let written = self.outputs.iter().filter(|(_, p)| is_clip(p)).chain(&self.output_dirs);
        for (option, out) in written {
            let Some(canon) = Key::of(out).path else { continue };
            for (data_option, data) in &self.data {
                let Ok(data_canon) = data.canonicalize() else { continue };
                if canon.starts_with(&data_canon) {
                    bail!(
                        "{option} {} is inside the dataset folder {data_option} {}: the output would join the dataset \
                         the next time it is read; write it outside that folder",
                        out.display(),
                        data.display()
                    );
                }
            }
        }
        Ok(())
    }
}

/// The file part of `FILE:FRAME` or `FILE:FROM:TO` (the whole text when it names a file).
pub fn clip_file_of(spec: &str) -> PathBuf {
    let mut s = spec;
    for _ in 0..2 {
        if Path::new(s).is_file() {
            break;
        }
        match s.rsplit_once(':') {
            Some((head, _)) => s = head,
            None => break,
        }
    }
    PathBuf::from(s)
}

/// What a path names: its canonical path (links resolved; for a file not yet written, its
/// folder's canonical path and its name) and, for an existing file, its device and inode.
struct Key {
    path: Option<PathBuf>,
    inode: Option<(u64, u64)>,
}

impl Key {
    fn of(p: &Path) -> Key {
        let path = p.canonicalize().ok().or_else(|| {
            let name = p.file_name()?;
            let parent = p.parent().filter(|d| !d.as_os_str().is_empty()).unwrap_or(Path::new("."));
            Some(parent.canonicalize().ok()?.join(name))
        });
        Key { path, inode: inode(p) }
    }

    fn same(&self, other: &Key) -> bool {
        (self.path.is_some() && self.path == other.path) || (self.inode.is_some() && self.inode == other.inode)
    }
}

#[cfg(unix)]
fn inode(p: &Path) -> Option<(u64, u64)> {
    use std::os::unix::fs::MetadataExt;
    std::fs::metadata(p).ok().map(|m| (m.dev(), m.ino()))
}

#[cfg(not(unix))]
fn inode(_: &Path) -> Option<(u64, u64)> {
    None
}

/// When `out` names a file of the run folder `run` (an existing `*.json` or `*.safetensors`
/// inside it, at any depth), that file's path relative to the run.
fn run_file(run: &Path, out: &Path) -> Option<String> {
    let run = run.canonicalize().ok()?;
    let key = Key::of(out);
    let path = key.path.as_ref()?;
    let inside = path.strip_prefix(&run).ok()?;
    let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("");
    (path.is_file() && matches!(ext, "json" | "safetensors")).then(|| inside.display().to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clip_specs_name_their_file() {
        assert_eq!(clip_file_of("no/such.bvh:20"), PathBuf::from("no/such.bvh"));
        assert_eq!(clip_file_of("no/such.bvh:5:40"), PathBuf::from("no/such.bvh"));
        assert_eq!(clip_file_of("plain.bvh"), PathBuf::from("plain.bvh"));
    }
}
