//! What the library's long tasks (benchmarks, training runs, dataset tools) share with their
//! callers: a [`Message`] error for input they refuse (said in words, with the fix), the
//! [`Context`] that prefixes a lower error with what was being done, and [`Progress`], which a
//! command line shows as a bar and code can ignore ([`Quiet`]).

use std::fmt::Display;

/// A refusal or failure said in words: what was wrong and how to fix it (`--valid-glob GLOB
/// matches no clip of DIR: ...`), with the context of the lower error it wraps, if any.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct Message(pub String);

impl Message {
    /// A message from anything that displays.
    pub fn new(text: impl Display) -> Self {
        Message(text.to_string())
    }
}

/// Returns early with a [`Message`] made by `format!` (converted into the function's error
/// type with `From`).
#[macro_export]
macro_rules! bail {
    ($($arg:tt)*) => {
        return Err($crate::report::Message(format!($($arg)*)).into())
    };
}

/// Prefixes an error (or a missing value) with what was being done: `context: cause`.
pub trait Context<T> {
    /// The error, or `None`, as a [`Message`] `context: cause`.
    fn context(self, context: impl Display) -> Result<T, Message>;
    /// [`Context::context`] with the context made only on failure.
    fn with_context<C: Display>(self, context: impl FnOnce() -> C) -> Result<T, Message>;
}

impl<T, E: Display> Context<T> for Result<T, E> {
    fn context(self, context: impl Display) -> Result<T, Message> {
        self.map_err(|e| Message(format!("{context}: {e}")))
    }

    fn with_context<C: Display>(self, context: impl FnOnce() -> C) -> Result<T, Message> {
        self.map_err(|e| Message(format!("{}: {e}", context())))
    }
}

impl<T> Context<T> for Option<T> {
    fn context(self, context: impl Display) -> Result<T, Message> {
        self.ok_or_else(|| Message(context.to_string()))
    }

    fn with_context<C: Display>(self, context: impl FnOnce() -> C) -> Result<T, Message> {
        self.ok_or_else(|| Message(context().to_string()))
    }
}

/// Progress of a long task, for a command line to show; every method does nothing by default.
pub trait Progress: Sync {
    /// A new stage, in a few words (`loading DIR`, `planning the test cases`): a spinner.
    fn stage(&self, _message: &str) {}
    /// `total` units of work follow (a bar from here on), described by `message`.
    fn start(&self, _total: u64, _message: &str) {}
    /// `units` more units done.
    fn advance(&self, _units: u64) {}
    /// What the unit in progress is (`sequence 3/10`, a method's name).
    fn note(&self, _message: &str) {}
    /// The task is over: the display is cleared.
    fn finish(&self) {}
    /// Something the user should read (a repaired or skipped input): a command line prints it
    /// on standard error.
    fn notice(&self, _message: &str) {}
}

/// No progress shown.
#[derive(Clone, Copy, Debug, Default)]
pub struct Quiet;

impl Progress for Quiet {}

#[cfg(test)]
mod tests {
    use super::*;

    fn refuse(n: usize) -> Result<(), Message> {
        if n > 2 {
            bail!("{n} is more than 2: pass at most 2");
        }
        Ok(())
    }

    #[test]
    fn messages_carry_their_context() {
        assert_eq!(refuse(3).unwrap_err().to_string(), "3 is more than 2: pass at most 2");
        let e = "x".parse::<u32>().context("reading --count").unwrap_err();
        assert!(e.to_string().starts_with("reading --count: invalid digit"), "{e}");
        let e = None::<u32>.with_context(|| format!("no {}", "clip")).unwrap_err();
        assert_eq!(e.to_string(), "no clip");
    }
}
