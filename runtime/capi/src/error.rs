//! What a C caller sees of an error: a `ZooStatus` and a message in C terms.
//!
//! `guard` runs the body of every C function: it catches panics and prefixes each message
//! with the function's name. `runtime_failure` gives the status of a runtime error and, with
//! `c_message`, a message that names C functions and C arguments where the runtime's names
//! Rust API (`TransitionRunner::start`, `StitchRefiner::set_window`, ...).

use crate::ZooStatus;
use std::cell::{Cell, RefCell};
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::Once;
use zoo_runtime::MotionError;
use zoo_runtime::metadata::MotionTaskKind;

thread_local! {
    static LAST_ERROR: RefCell<String> = const { RefCell::new(String::new()) };
    /// Whether the thread runs the body of a C function (inside `guard`): a panic there is
    /// recorded, not printed.
    static IN_CALL: Cell<bool> = const { Cell::new(false) };
    /// The message and place of the last panic caught inside a C function.
    static PANIC: RefCell<String> = const { RefCell::new(String::new()) };
}

/// An error status and its message (without the function's name, which `guard` adds).
pub(crate) type Failure = (ZooStatus, String);

/// Calls `f` with the calling thread's last error message.
pub(crate) fn with_last_error<R>(f: impl FnOnce(&str) -> R) -> R {
    LAST_ERROR.with(|e| f(&e.borrow()))
}

/// Records `message` as the calling thread's last error, prefixed with `function`.
pub(crate) fn set_error(function: &str, message: &str) {
    LAST_ERROR.with(|e| {
        let mut e = e.borrow_mut();
        e.clear();
        e.push_str(function);
        e.push_str(": ");
        e.push_str(message);
    });
}

/// Clears the calling thread's last error (a successful call). Allocates nothing.
fn clear_error() {
    LAST_ERROR.with(|e| {
        if let Ok(mut e) = e.try_borrow_mut() {
            e.clear();
        }
    });
}

/// Installs, once per process, a panic hook that keeps the library quiet: a panic inside a C
/// function is recorded for its error message and never printed (no message, no backtrace on
/// stderr, whatever `RUST_BACKTRACE` says); a panic elsewhere in the process (a Rust host's own
/// code) goes to the hook that was installed before.
fn install_quiet_panic_hook() {
    static HOOK: Once = Once::new();
    HOOK.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if IN_CALL.with(Cell::get) {
                let what = info
                    .payload()
                    .downcast_ref::<&str>()
                    .map(|s| s.to_string())
                    .or_else(|| info.payload().downcast_ref::<String>().cloned())
                    .unwrap_or_else(|| "unknown panic".into());
                let at = info.location().map(|l| format!(" at {}:{}", l.file(), l.line())).unwrap_or_default();
                PANIC.with(|p| *p.borrow_mut() = format!("{what}{at}"));
            } else {
                previous(info);
            }
        }));
    });
}

/// Runs the body `f` of the C function `function`: on success clears the thread's last error;
/// on an error records its message (prefixed with the function's name); turns a panic into
/// `ZooStatus::Panic` with the panic's message as the last error, printing nothing. Allocates
/// nothing when `f` succeeds.
pub(crate) fn guard(function: &str, f: impl FnOnce() -> Result<(), Failure>) -> ZooStatus {
    install_quiet_panic_hook();
    let outer = IN_CALL.with(|c| c.replace(true));
    let result = catch_unwind(AssertUnwindSafe(f));
    IN_CALL.with(|c| c.set(outer));
    match result {
        Ok(Ok(())) => {
            clear_error();
            ZooStatus::Ok
        }
        Ok(Err((status, message))) => {
            set_error(function, &message);
            status
        }
        Err(_) => {
            let what = PANIC.with(|p| std::mem::take(&mut *p.borrow_mut()));
            set_error(function, &format!("internal error in the zoo runtime ({what}); please report it"));
            ZooStatus::Panic
        }
    }
}

/// The status of a runtime error and its message in C terms (`c_message`).
pub(crate) fn runtime_failure(e: MotionError) -> Failure {
    let status = match &e {
        MotionError::Io { .. }
        | MotionError::Format(_)
        | MotionError::NotOnnx { .. }
        | MotionError::NoTask { .. }
        | MotionError::BadGraphIo { .. }
        | MotionError::Unsupported { .. } => ZooStatus::LoadFailed,
        MotionError::WrongTask { .. } => ZooStatus::WrongModel,
        MotionError::BufferCount { .. }
        | MotionError::BufferLength { .. }
        | MotionError::NonFinite { .. }
        | MotionError::StateMismatch { .. }
        | MotionError::EmptyBatch
        | MotionError::Keys { .. }
        | MotionError::Stitch { .. }
        | MotionError::Control { .. } => ZooStatus::InvalidArgument,
        MotionError::TransitionSequence { .. } | MotionError::BeyondTrainedLength { .. } => ZooStatus::InvalidState,
        MotionError::Run { .. } => ZooStatus::RunFailed,
    };
    (status, c_message(&e))
}

/// The functions that run a model of `task`, for messages.
pub(crate) fn functions_of(task: MotionTaskKind) -> &'static str {
    match task {
        MotionTaskKind::Transition => "zoo_transition_*",
        MotionTaskKind::Keyframes => "zoo_keyframes_*",
        MotionTaskKind::Stitch => "zoo_stitch_*",
        MotionTaskKind::Synthesis => "zoo_synthesis_* (and zoo_control_*)",
        MotionTaskKind::Step => "no function of this C ABI (a bare step graph has no task)",
    }
}

/// Rust API named in the runtime's messages, and what a C caller calls instead. Applied in
/// order, so a longer name comes before a shorter one it contains.
const RUST_TO_C: [(&str, &str); 14] = [
    ("TransitionState::set_heightmap(None)", "zoo_transition_set_heightmap with no heights"),
    ("TransitionState::set_heightmap", "zoo_transition_set_heightmap"),
    ("TransitionRunner::begin_batch", "zoo_transition_begin or zoo_transition_begin_posed"),
    (
        "begun from positions (begin_batch); feed it positions (feed_batch)",
        "begun from positions (zoo_transition_begin); feed it positions (zoo_transition_feed)",
    ),
    ("TransitionRunner::start", "zoo_transition_start or zoo_transition_start_posed"),
    (
        "started from positions (start); start it with start_posed",
        "started from positions (zoo_transition_start); start it with zoo_transition_start_posed",
    ),
    ("StitchRefiner::set_window", "zoo_stitch_set_window"),
    ("StitchRefiner::stream", "zoo_stitch_stream_new"),
    ("StitchRefiner::skeleton", "zoo_model_skeleton"),
    ("allocate the poses with EnginePose::new(refiner.joints())", "size the buffers from zoo_model_info's `joints`"),
    ("allocate it with EnginePose::new(refiner.joints())", "size the buffers from zoo_model_info's `joints`"),
    ("SynthesisCharacter::start", "zoo_synthesis_start"),
    ("ControlledCharacter::start", "zoo_control_start"),
    ("pass `fixed: &[]`", "pass `fixed` NULL and `fixed_len` 0"),
];

/// The message of a runtime error in C terms: the variants whose message names Rust API are
/// rebuilt from their fields; the others' text has every Rust name of `RUST_TO_C` replaced by
/// its C equivalent.
pub(crate) fn c_message(e: &MotionError) -> String {
    match e {
        MotionError::WrongTask { task, kind, expected, .. } => {
            let runs = MotionTaskKind::from_name(task).map_or("no function of this C ABI", functions_of);
            format!("the model is a `{task}` model (kind `{kind}`), not a `{expected}` model; run it with {runs}")
        }
        MotionError::NoTask { kind } => format!(
            "the model (kind `{kind}`) is a bare step graph with no task; this C ABI runs models of a task \
             (transition, keyframes, stitch, synthesis): export a trained model with `zoo export --onnx RUN_DIR`"
        ),
        MotionError::StateMismatch { name, expected, found } => format!(
            "the characters do not fit the runner's model (state `{name}`: expected {expected} values, found \
             {found}); make the runner and the characters from the same model"
        ),
        MotionError::BeyondTrainedLength { requested, trained } => format!(
            "a transition of {requested} frames is longer than the {trained} frames this model was trained for \
             (beyond its training length the network drifts from the target); pass a `length` of at most \
             {trained} (zoo_transition_info's `transition_frames`), or opt in with \
             zoo_transition_allow_beyond_trained(runner, true)"
        ),
        e => translate(&e.to_string()),
    }
}

/// `message` with every Rust name of `RUST_TO_C` replaced by its C equivalent.
fn translate(message: &str) -> String {
    let mut out = message.to_string();
    for (rust, c) in RUST_TO_C {
        if out.contains(rust) {
            out = out.replace(rust, c);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::Path;

    /// The string literals of Rust source `src` (escapes resolved, line continuations joined),
    /// up to its `#[cfg(test)]` module; comments skipped.
    fn string_literals(src: &str) -> Vec<String> {
        let src = src.split("#[cfg(test)]").next().unwrap_or_default();
        let c: Vec<char> = src.chars().collect();
        let mut out = Vec::new();
        let mut i = 0;
        let ident = |ch: char| ch.is_alphanumeric() || ch == '_';
        while i < c.len() {
            let prev_ident = i > 0 && ident(c[i - 1]);
            match c[i] {
                '/' if c.get(i + 1) == Some(&'/') => {
                    while i < c.len() && c[i] != '\n' {
                        i += 1;
                    }
                }
                '/' if c.get(i + 1) == Some(&'*') => {
                    while i + 1 < c.len() && !(c[i] == '*' && c[i + 1] == '/') {
                        i += 1;
                    }
                    i += 2;
                }
                'r' if !prev_ident && matches!(c.get(i + 1), Some('"' | '#')) => {
                    let mut j = i + 1;
                    while c.get(j) == Some(&'#') {
                        j += 1;
                    }
                    if c.get(j) != Some(&'"') {
                        i += 1;
                        continue;
                    }
                    let hashes = j - i - 1;
                    let mut s = String::new();
                    j += 1;
                    while j < c.len() && !(c[j] == '"' && (0..hashes).all(|h| c.get(j + 1 + h) == Some(&'#'))) {
                        s.push(c[j]);
                        j += 1;
                    }
                    out.push(s);
                    i = j + 1 + hashes;
                }
                '"' => {
                    let mut s = String::new();
                    let mut j = i + 1;
                    while j < c.len() && c[j] != '"' {
                        if c[j] == '\\' {
                            j += 1;
                            match c.get(j) {
                                Some('\n') => {
                                    while c.get(j + 1).is_some_and(|ch| ch.is_whitespace()) {
                                        j += 1;
                                    }
                                }
                                Some('n') => s.push('\n'),
                                Some(&other) => s.push(other),
                                None => {}
                            }
                        } else {
                            s.push(c[j]);
                        }
                        j += 1;
                    }
                    out.push(s);
                    i = j + 1;
                }
                '\'' => {
                    // A char literal ('x', '\n', '"') or a lifetime ('a).
                    if c.get(i + 1) == Some(&'\\') {
                        let mut j = i + 2;
                        while j < c.len() && c[j] != '\'' {
                            j += 1;
                        }
                        i = j + 1;
                    } else if c.get(i + 2) == Some(&'\'') {
                        i += 3;
                    } else {
                        i += 1;
                    }
                }
                _ => i += 1,
            }
        }
        out
    }

    fn rust_files(dir: &Path, files: &mut Vec<std::path::PathBuf>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                rust_files(&path, files);
            } else if path.extension().is_some_and(|e| e == "rs") {
                files.push(path);
            }
        }
    }

    /// The public type names of the runtime and the format crate with two capitals or more
    /// (`TransitionRunner`, `EnginePose`): Rust names a C caller has no use for.
    fn rust_type_names(sources: &[String]) -> Vec<String> {
        let mut names = Vec::new();
        for src in sources {
            for line in src.lines() {
                let line = line.trim_start();
                for item in ["pub struct ", "pub enum ", "pub trait ", "pub type "] {
                    if let Some(rest) = line.strip_prefix(item) {
                        let name: String = rest.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
                        if name.chars().filter(|c| c.is_uppercase()).count() >= 2 {
                            names.push(name);
                        }
                    }
                }
            }
        }
        names.sort();
        names.dedup();
        names
    }

    /// Whether `text` holds `word` not inside a longer identifier.
    fn has_word(text: &str, word: &str) -> bool {
        let ident = |c: char| c.is_alphanumeric() || c == '_';
        text.match_indices(word).any(|(at, _)| {
            let before = text[..at].chars().next_back().is_none_or(|c| !ident(c));
            let after = text[at + word.len()..].chars().next().is_none_or(|c| !ident(c));
            before && after
        })
    }

    /// Literals whose Rust names a C caller never sees: the messages `c_message` rebuilds from
    /// the error's fields, and the hints of `WrongTask` (which it drops).
    const REBUILT: [&str; 6] = [
        "takes only `{expected}` models",
        "is a bare step graph with no task",
        "create it with MotionModel::new_state",
        "opt in with TransitionRunner::allow_beyond_trained",
        "model runs with ",
        "graph runs with MotionModel",
    ];

    /// Every string literal of the runtime's sources (its messages among them), translated as
    /// the C ABI translates a message, names no Rust path (`Type::method`) and no Rust type,
    /// unless its variant's message is rebuilt in C terms; and every rebuilt message is still
    /// in the runtime (the list is not stale).
    #[test]
    fn runtime_messages_name_no_rust_api_after_translation() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
        let mut files = Vec::new();
        rust_files(&root.join("runtime/runtime/src"), &mut files);
        rust_files(&root.join("core/format/src"), &mut files);
        // The ONNX protobuf declarations: prost attributes, no messages.
        files.retain(|f| !f.ends_with("format/src/pb.rs"));
        files.sort();
        let sources: Vec<String> = files.iter().map(|f| std::fs::read_to_string(f).unwrap()).collect();
        let types = rust_type_names(&sources);
        assert!(types.iter().any(|t| t == "TransitionRunner"), "the scan finds the runtime's types: {types:?}");
        let mut rebuilt_seen = [false; REBUILT.len()];
        let mut bad = Vec::new();
        let mut scanned = 0;
        for (file, src) in files.iter().zip(&sources) {
            for literal in string_literals(src) {
                scanned += 1;
                if let Some(r) = REBUILT.iter().position(|r| literal.contains(r)) {
                    rebuilt_seen[r] = true;
                    continue;
                }
                // One word is a name, not a message: a serde attribute's function
                // (`Vec::is_empty`), the `loader` of `MotionError::WrongTask` (whose message is
                // rebuilt).
                if literal.chars().all(|c| c.is_alphanumeric() || c == '_' || c == ':') {
                    continue;
                }
                let c = translate(&literal);
                let path = c
                    .match_indices("::")
                    .any(|(at, _)| c[..at].chars().next_back().is_some_and(|ch| ch.is_alphanumeric() || ch == '_'));
                let named: Vec<&String> = types.iter().filter(|t| has_word(&c, t)).collect();
                if path || !named.is_empty() {
                    bad.push(format!("{}: {c:?} (types {named:?})", file.display()));
                }
            }
        }
        assert!(scanned > 100, "the scan reads the runtime's literals ({scanned})");
        assert!(bad.is_empty(), "runtime messages that name Rust API after translation:\n{}", bad.join("\n"));
        for (r, seen) in REBUILT.iter().zip(rebuilt_seen) {
            assert!(seen, "no runtime literal contains `{r}` any more: update REBUILT and c_message");
        }
    }

    #[test]
    fn rebuilt_messages_name_c_functions() {
        let cases = [
            (
                MotionError::WrongTask {
                    task: "stitch".into(),
                    kind: "rmr".into(),
                    expected: "transition",
                    loader: "TransitionModel",
                    hint: "a `stitch` model runs with StitchRefiner",
                },
                "run it with zoo_stitch_*",
            ),
            (MotionError::NoTask { kind: "toy".into() }, "zoo export --onnx RUN_DIR"),
            (
                MotionError::StateMismatch { name: "h".into(), expected: 3, found: 4 },
                "make the runner and the characters from the same model",
            ),
            (
                MotionError::BeyondTrainedLength { requested: 31, trained: 30 },
                "zoo_transition_allow_beyond_trained(runner, true)",
            ),
        ];
        for (e, needle) in cases {
            let rust = e.to_string();
            let c = c_message(&e);
            assert!(c.contains(needle), "{c}");
            assert!(!c.contains("::"), "{c}");
            assert!(rust != c);
        }
    }

    #[test]
    fn translated_messages_name_c_functions() {
        let cases = [
            (
                MotionError::TransitionSequence {
                    character: 0,
                    reason: "start the transition (TransitionRunner::start) before stepping it".into(),
                },
                "character 0: start the transition (zoo_transition_start or zoo_transition_start_posed) before stepping it",
            ),
            (
                MotionError::TransitionSequence {
                    character: 1,
                    reason: "this model is terrain-aware and the character's heightmap was removed \
                             (TransitionState::set_heightmap(None)) during the transition"
                        .into(),
                },
                "(zoo_transition_set_heightmap with no heights)",
            ),
            (
                MotionError::Stitch { reason: "plan a shorter window with StitchRefiner::set_window".into() },
                "stitching: plan a shorter window with zoo_stitch_set_window",
            ),
            (
                MotionError::Control {
                    reason: "the character was not started: call ControlledCharacter::start with its seed frames first"
                        .into(),
                },
                "call zoo_control_start with its seed frames first",
            ),
        ];
        for (e, want) in cases {
            let c = c_message(&e);
            assert!(c.contains(want), "`{c}` should contain `{want}`");
        }
    }

    #[test]
    fn every_error_has_a_status() {
        let (status, message) = runtime_failure(MotionError::WrongTask {
            task: "keyframes".into(),
            kind: "arnn".into(),
            expected: "stitch",
            loader: "StitchRefiner",
            hint: "",
        });
        assert_eq!(status, ZooStatus::WrongModel);
        assert!(message.contains("run it with zoo_keyframes_*"), "{message}");
        assert_eq!(runtime_failure(MotionError::EmptyBatch).0, ZooStatus::InvalidArgument);
        assert_eq!(runtime_failure(MotionError::Run { reason: "x".into() }).0, ZooStatus::RunFailed);
    }

    #[test]
    fn the_literal_scanner_reads_continued_and_raw_strings() {
        let src = "let a = \"one \\\n     two\"; let c = '\"'; let l: &'a str = r#\"r\"aw\"#; // \"no\"\n";
        assert_eq!(string_literals(src), ["one two", "r\"aw"]);
    }

    #[test]
    fn guard_prefixes_the_function_and_catches_panics() {
        let status = guard("zoo_test_call", || Err((ZooStatus::InvalidArgument, "`x` is bad".into())));
        assert_eq!(status, ZooStatus::InvalidArgument);
        assert_eq!(with_last_error(str::to_string), "zoo_test_call: `x` is bad");
        let status = guard("zoo_test_panic", || panic!("boom"));
        assert_eq!(status, ZooStatus::Panic);
        assert!(with_last_error(|m| m.starts_with("zoo_test_panic: internal error") && m.contains("boom")));
    }
}
