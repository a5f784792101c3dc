//! What keeps a good run from being lost: the lock that keeps a second training out of a run
//! folder, the old run that `--overwrite` keeps aside until the new run has finished its first
//! epoch (and puts back when it fails before), and the leftovers of interrupted writes (temporary
//! files and folders) cleared once the folder is locked, so they never block the next command.

use crate::error::TrainError;
use std::io::Write as _;
use std::path::{Path, PathBuf};
use std::sync::{Mutex, MutexGuard};

/// The lock file in a run folder: the process id and start time of the training writing it.
pub const LOCK_FILE: &str = ".zoo-train.lock";

/// Where `--overwrite` keeps the old run until the new one has finished its first epoch.
pub const ASIDE_DIR: &str = ".previous-run";

/// The locks this process holds and the run folders whose old run is kept aside.
struct Held {
    locks: Vec<PathBuf>,
    asides: Vec<PathBuf>,
}

static HELD: Mutex<Held> = Mutex::new(Held { locks: Vec::new(), asides: Vec::new() });

fn held() -> MutexGuard<'static, Held> {
    HELD.lock().unwrap_or_else(|e| e.into_inner())
}

fn config(message: String) -> TrainError {
    TrainError::Config(message)
}

fn key(dir: &Path) -> PathBuf {
    std::fs::canonicalize(dir).unwrap_or_else(|_| dir.to_path_buf())
}

/// Whether process `pid` runs (`None`: this system cannot tell).
fn alive(pid: u32) -> Option<bool> {
    let proc = Path::new("/proc");
    proc.join("self").exists().then(|| proc.join(pid.to_string()).exists())
}

/// The lock's holder: (pid, start time as written, the process's start as [`process_start`]
/// gave it when the lock was taken).
fn holder(text: &str) -> (Option<u32>, String, Option<String>) {
    let field = |name: &str| text.lines().find_map(|l| l.strip_prefix(name)).map(str::trim);
    (
        field("pid ").and_then(|p| p.parse().ok()),
        field("started ").unwrap_or("at an unknown time").to_string(),
        field("process-start ").map(str::to_string),
    )
}

/// When process `pid` started, as the kernel tells it (`/proc/sys/kernel/random/boot_id` and
/// the start time in clock ticks since boot, field 22 of `/proc/PID/stat`): a process id used
/// again by another process has another start, so a lock outliving its process is told apart
/// from a running training even when its process id was given to another process.
fn process_start(pid: u32) -> Option<String> {
    let boot = std::fs::read_to_string("/proc/sys/kernel/random/boot_id").ok()?;
    let stat = std::fs::read_to_string(format!("/proc/{pid}/stat")).ok()?;
    let after_name = &stat[stat.rfind(')')? + 1..];
    let ticks = after_name.split_whitespace().nth(19)?;
    Some(format!("{} {ticks}", boot.trim()))
}

/// Seconds since 1970 as `YYYY-MM-DD HH:MM:SS UTC` (the civil-from-days algorithm of
/// H. Hinnant's date library; no date crate is needed for one line of a lock file).
fn utc(secs: u64) -> String {
    let (days, rem) = ((secs / 86_400) as i64, secs % 86_400);
    let z = days + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let d = doy - (153 * mp + 2) / 5 + 1;
    let m = if mp < 10 { mp + 3 } else { mp - 9 };
    let y = yoe + era * 400 + i64::from(m <= 2);
    format!("{y:04}-{m:02}-{d:02} {:02}:{:02}:{:02} UTC", rem / 3600, rem / 60 % 60, rem % 60)
}

/// Locks run folder `dir` (created if missing) for this process until [`end_of_command`]: a
/// second training into it is refused with the first one's process id and start time while
/// that process runs; the lock of a process that no longer runs is taken over, with a note.
/// Once locked, the leftovers of interrupted writes in the folder are removed.
pub fn lock(dir: &Path) -> Result<(), TrainError> {
    std::fs::create_dir_all(dir).map_err(|e| config(format!("{}: cannot create the folder: {e}", dir.display())))?;
    let k = key(dir);
    if held().locks.contains(&k) {
        return Ok(());
    }
    let path = dir.join(LOCK_FILE);
    let started = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.as_secs());
    let mut me = format!("pid {}\nstarted {}\n", std::process::id(), utc(started));
    if let Some(start) = process_start(std::process::id()) {
        me.push_str(&format!("process-start {start}\n"));
    }
    for _ in 0..3 {
        match std::fs::OpenOptions::new().write(true).create_new(true).open(&path) {
            Ok(mut f) => {
                f.write_all(me.as_bytes())
                    .and_then(|()| f.sync_all())
                    .map_err(|e| config(format!("{}: cannot write the lock file: {e}", path.display())))?;
                held().locks.push(k);
                clear_interrupted(dir);
                return put_back_unfinished(dir);
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {
                let (pid, when, start) = holder(&std::fs::read_to_string(&path).unwrap_or_default());
                match pid.map(|p| (p, alive(p))) {
                    Some((p, _)) if p == std::process::id() => {}
                    Some((p, Some(true)))
                        if start.is_some() && process_start(p).is_some_and(|now| Some(now) != start) =>
                    {
                        eprintln!(
                            "{}: taking over the lock of process {p} (started {when}), which no longer runs (its \
                             process id now belongs to another process)",
                            dir.display()
                        )
                    }
                    Some((p, Some(true))) => {
                        return Err(config(format!(
                            "{} is in use by another training: process {p}, started {when} (lock file {}); wait \
                             for it to end or choose another folder (if process {p} is not a zoo training, delete \
                             the lock file)",
                            dir.display(),
                            path.display()
                        )));
                    }
                    Some((p, None)) => {
                        return Err(config(format!(
                            "{} is locked by process {p}, started {when} ({}); if that process no longer runs, \
                             delete the lock file",
                            dir.display(),
                            path.display()
                        )));
                    }
                    Some((p, Some(false))) => eprintln!(
                        "{}: taking over the lock of process {p} (started {when}), which no longer runs",
                        dir.display()
                    ),
                    None => eprintln!("{}: taking over an unreadable lock file", dir.display()),
                }
                let _ = std::fs::remove_file(&path);
            }
            Err(e) => return Err(config(format!("{}: cannot create the lock file: {e}", path.display()))),
        }
    }
    Err(config(format!("{}: cannot take the lock (another process keeps taking it)", path.display())))
}

/// Removes the temporary files and folders (`.NAME.tmp`, `.NAME.PID.tmp`) that an interrupted
/// write left in `dir` and its sub-folders, and says how many. Only called under the lock, so
/// no other writer owns them.
fn clear_interrupted(dir: &Path) {
    let mut removed = Vec::new();
    let mut folders = vec![dir.to_path_buf()];
    // The run folder and one level of sub-folders (`last/`, a model's stage folders).
    if let Ok(entries) = std::fs::read_dir(dir) {
        folders.extend(entries.flatten().map(|e| e.path()).filter(|p| p.is_dir()));
    }
    for folder in folders {
        let Ok(entries) = std::fs::read_dir(&folder) else { continue };
        for p in entries.flatten().map(|e| e.path()) {
            let name = p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
            if !(name.starts_with('.') && name.ends_with(".tmp")) {
                continue;
            }
            let r = if p.is_dir() { std::fs::remove_dir_all(&p) } else { std::fs::remove_file(&p) };
            if r.is_ok() {
                removed.push(name);
            }
        }
    }
    if !removed.is_empty() {
        eprintln!(
            "{}: removed {} leftover(s) of an interrupted write ({})",
            dir.display(),
            removed.len(),
            removed.join(", ")
        );
    }
}

/// A run kept aside by an `--overwrite` that never finished its first epoch (the process was
/// killed) is put back when the folder holds no newer run.
fn put_back_unfinished(dir: &Path) -> Result<(), TrainError> {
    let aside = dir.join(ASIDE_DIR);
    if !aside.is_dir() || held().asides.contains(&key(dir)) {
        return Ok(());
    }
    if crate::train_loop::read_state(dir).is_ok_and(|s| s.epoch > 0) {
        let _ = std::fs::remove_dir_all(&aside);
        return Ok(());
    }
    put_back(dir)?;
    eprintln!(
        "{}: put back the run that an interrupted --overwrite had kept aside in {ASIDE_DIR}/ (the new run never \
         finished an epoch)",
        dir.display()
    );
    Ok(())
}

/// Moves the files and folders `names` of `out` into `out/.previous-run/` (what `--overwrite`
/// does instead of deleting them): they are deleted when the new run has finished its first
/// epoch ([`epoch_done`]) and put back when the command fails before ([`end_of_command`]).
pub fn set_aside(out: &Path, names: &[&str]) -> Result<(), TrainError> {
    let aside = out.join(ASIDE_DIR);
    if aside.exists() {
        std::fs::remove_dir_all(&aside)
            .map_err(|e| config(format!("--overwrite: cannot clear {}: {e}", aside.display())))?;
    }
    std::fs::create_dir_all(&aside)
        .map_err(|e| config(format!("--overwrite: cannot create {}: {e}", aside.display())))?;
    for name in names {
        let p = out.join(name);
        if p.exists() {
            let to = aside.join(name);
            if let Some(parent) = to.parent() {
                let _ = std::fs::create_dir_all(parent);
            }
            std::fs::rename(&p, &to)
                .map_err(|e| config(format!("--overwrite: cannot move {} aside: {e}", p.display())))?;
        }
    }
    held().asides.push(key(out));
    println!(
        "--overwrite: the run in {} is kept in {ASIDE_DIR}/ until the new run has finished its first epoch",
        out.display()
    );
    Ok(())
}

/// Moves everything in `out/.previous-run/` back into `out` (over the new run's files).
fn put_back(out: &Path) -> Result<(), TrainError> {
    let aside = out.join(ASIDE_DIR);
    let fail = |e: std::io::Error| config(format!("cannot put back the old run from {}: {e}", aside.display()));
    // The new run's record of its options is not the old run's: a resume would read them.
    if !aside.join(super::COMMAND_FILE).exists() && out.join(super::COMMAND_FILE).is_file() {
        std::fs::remove_file(out.join(super::COMMAND_FILE)).map_err(fail)?;
    }
    for entry in std::fs::read_dir(&aside).map_err(fail)?.flatten() {
        let to = out.join(entry.file_name());
        if to.is_dir() {
            std::fs::remove_dir_all(&to).map_err(fail)?;
        } else if to.exists() {
            std::fs::remove_file(&to).map_err(fail)?;
        }
        std::fs::rename(entry.path(), &to).map_err(fail)?;
    }
    std::fs::remove_dir_all(&aside).map_err(fail)
}

/// Held while a training writes its checkpoint ([`checkpoint_writing`]): a stop on a signal
/// ([`stop_on_signal`]) waits for the write to end, so that the checkpoint it keeps is whole.
static WRITING: Mutex<()> = Mutex::new(());

/// Taken by the training loop for the time it writes an epoch's checkpoint (see [`WRITING`]).
pub fn checkpoint_writing() -> MutexGuard<'static, ()> {
    WRITING.lock().unwrap_or_else(|e| e.into_inner())
}

/// A training stopped by a signal (`SIGINT`, `SIGTERM`; called from the thread that receives
/// it): once a checkpoint write in progress has ended, says that the training stopped, which
/// checkpoint is kept and how to continue it, puts back an old run kept aside by an
/// `--overwrite` that never finished an epoch, releases the locks, and exits with 128 + the
/// signal's number (130 for SIGINT, 143 for SIGTERM), never 0.
pub fn stop_on_signal(name: &str, number: i32) -> ! {
    let writing = checkpoint_writing();
    let dirs: Vec<PathBuf> = held().locks.clone();
    let mut kept = String::new();
    for dir in &dirs {
        kept.push_str(&match crate::train_loop::read_state(dir) {
            Ok(s) if s.epoch > 0 => format!(
                "; the checkpoint of epoch {} in {} is kept: continue it with `--resume {}`",
                s.epoch,
                dir.display(),
                dir.display()
            ),
            _ => format!("; {} holds no finished epoch yet", dir.display()),
        });
    }
    eprintln!("zoo: stopped by {name} before the training finished{kept}");
    end_of_command(false);
    drop(writing);
    std::process::exit(128 + number)
}

/// Called by the training loop when an epoch's checkpoint of the run in `dir` is written: an
/// old run kept aside for `dir` (or for a folder above it: a model's stage folder) is deleted.
pub fn epoch_done(dir: &Path) {
    let k = key(dir);
    let mut h = held();
    let done: Vec<PathBuf> = h.asides.iter().filter(|a| k.starts_with(a)).cloned().collect();
    h.asides.retain(|a| !done.contains(a));
    drop(h);
    for out in done {
        match std::fs::remove_dir_all(out.join(ASIDE_DIR)) {
            Ok(()) => println!("--overwrite: the new run finished its first epoch; the old run is deleted"),
            Err(e) => eprintln!("--overwrite: cannot delete {}: {e}", out.join(ASIDE_DIR).display()),
        }
    }
}

/// The end of a command: when it failed (`ok` false), every old run still kept aside is put
/// back (the new run never finished an epoch); every lock this process holds is released.
pub fn end_of_command(ok: bool) {
    let mut h = held();
    let (asides, locks) = (std::mem::take(&mut h.asides), std::mem::take(&mut h.locks));
    drop(h);
    for out in asides {
        if ok {
            let _ = std::fs::remove_dir_all(out.join(ASIDE_DIR));
            continue;
        }
        match put_back(&out) {
            Ok(()) => eprintln!(
                "--overwrite: the new run failed before its first epoch; the old run in {} is back",
                out.display()
            ),
            Err(e) => eprintln!("{e}"),
        }
    }
    for dir in locks {
        let _ = std::fs::remove_file(dir.join(LOCK_FILE));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dates_are_utc() {
        assert_eq!(utc(0), "1970-01-01 00:00:00 UTC");
        assert_eq!(utc(1_795_000_000), "2026-11-18 11:06:40 UTC"); // `date -u -d @1795000000`
    }

    #[test]
    fn a_lock_of_a_running_process_refuses_and_a_dead_ones_is_taken_over() {
        let dir = tempfile::tempdir().unwrap();
        // Process 1 (init) always runs.
        std::fs::write(dir.path().join(LOCK_FILE), "pid 1\nstarted 2026-01-01 00:00:00 UTC\n").unwrap();
        let e = lock(dir.path()).unwrap_err().to_string();
        assert!(e.contains("in use by another training: process 1, started 2026-01-01 00:00:00 UTC"), "{e}");
        // A pid past the kernel's limit never runs.
        std::fs::write(dir.path().join(LOCK_FILE), "pid 4294967\nstarted 2026-01-01 00:00:00 UTC\n").unwrap();
        std::fs::write(dir.path().join(".config.json.77.tmp"), "").unwrap();
        std::fs::create_dir_all(dir.path().join(".last.tmp")).unwrap();
        lock(dir.path()).unwrap();
        let text = std::fs::read_to_string(dir.path().join(LOCK_FILE)).unwrap();
        assert!(text.starts_with(&format!("pid {}\n", std::process::id())), "{text}");
        assert!(!dir.path().join(".config.json.77.tmp").exists() && !dir.path().join(".last.tmp").exists());
        end_of_command(true);
        assert!(!dir.path().join(LOCK_FILE).exists());
        // Process 1 runs, but it is not the process that took the lock (another start): the
        // process id was used again, and the lock is taken over.
        if let Some(start) = process_start(1) {
            assert!(text.contains("process-start "), "{text}");
            let stale = format!("pid 1\nstarted 2026-01-01 00:00:00 UTC\nprocess-start {start}9\n");
            std::fs::write(dir.path().join(LOCK_FILE), stale).unwrap();
            lock(dir.path()).unwrap();
            end_of_command(true);
            let same = format!("pid 1\nstarted 2026-01-01 00:00:00 UTC\nprocess-start {start}\n");
            std::fs::write(dir.path().join(LOCK_FILE), same).unwrap();
            assert!(lock(dir.path()).unwrap_err().to_string().contains("if process 1 is not a zoo training, delete"));
        }
    }
}
