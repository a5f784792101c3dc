//! What the library says about itself and its errors: the last error of a thread
//! (`zoo_last_error`), the name of a status (`zoo_status_string`), the library's version
//! (`zoo_version_string`) and a logging callback for its warnings (`zoo_set_log_callback`).
//! The library never writes to stdout or stderr: a caught panic becomes the last error, and
//! warnings go to the callback (or nowhere without one).

use crate::error::{guard, with_last_error};
use crate::{ZOO_ABI_VERSION, ZooStatus};
use std::ffi::{CString, c_char, c_void};
use std::sync::RwLock;

/// Copies the calling thread's last error message into `buffer` (at most `capacity` bytes,
/// NUL-terminated, truncated if needed) and returns the message's full length in bytes without
/// the NUL. `buffer` may be NULL to ask for the length.
///
/// The contract: every function that returns a `ZooStatus` sets the calling thread's last error:
/// it is empty (length 0) after `ZOO_STATUS_OK` and holds the failed call's message after any
/// other status, until the thread's next such call. Functions that return no status (the `_free`
/// functions, `zoo_model_task`, `zoo_abi_version`, `zoo_version_string`, `zoo_status_string`
/// and this one) leave it as it is. Thread-safe: each thread has its own.
///
/// Safety: `buffer` is NULL or valid for `capacity` bytes of writes.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_last_error(buffer: *mut c_char, capacity: usize) -> usize {
    with_last_error(|message| {
        if !buffer.is_null() && capacity > 0 {
            let n = message.len().min(capacity - 1);
            // SAFETY: the caller gives `capacity` writable bytes; n + 1 <= capacity.
            unsafe {
                std::ptr::copy_nonoverlapping(message.as_ptr(), buffer.cast::<u8>(), n);
                buffer.add(n).write(0);
            }
        }
        message.len()
    })
}

/// The name of a status as a static NUL-terminated string (`"ZOO_STATUS_OK"`, ...), or
/// `"ZOO_STATUS_UNKNOWN"` for a value that is not a `ZooStatus`. Never NULL; do not free it.
/// Thread-safe. The status is passed as an integer so that any value is safe to pass.
#[unsafe(no_mangle)]
pub extern "C" fn zoo_status_string(status: i32) -> *const c_char {
    let name: &'static [u8] = match status {
        0 => b"ZOO_STATUS_OK\0",
        1 => b"ZOO_STATUS_NULL_POINTER\0",
        2 => b"ZOO_STATUS_INVALID_ARGUMENT\0",
        3 => b"ZOO_STATUS_LOAD_FAILED\0",
        4 => b"ZOO_STATUS_WRONG_MODEL\0",
        5 => b"ZOO_STATUS_INVALID_STATE\0",
        6 => b"ZOO_STATUS_RUN_FAILED\0",
        7 => b"ZOO_STATUS_NOT_AVAILABLE\0",
        8 => b"ZOO_STATUS_PANIC\0",
        _ => b"ZOO_STATUS_UNKNOWN\0",
    };
    name.as_ptr().cast()
}

/// The library's version as a static NUL-terminated string, `"zoo X.Y.Z (C ABI N)"`: the
/// release of zoo it was built from and its `ZOO_ABI_VERSION`. Never NULL; do not free it.
/// Thread-safe.
#[unsafe(no_mangle)]
pub extern "C" fn zoo_version_string() -> *const c_char {
    VERSION.as_ptr().cast()
}

const VERSION: &str = concat!("zoo ", env!("CARGO_PKG_VERSION"), " (C ABI 3)\0");
const _: () = assert!(ZOO_ABI_VERSION == 3, "update VERSION's C ABI number");

/// The severity of a log message.
#[repr(C)]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ZooLogLevel {
    /// Something failed and was worked around or reported as a status.
    Error = 1,
    /// Something the engine programmer should know (the library degraded or ignored something).
    Warning = 2,
    /// What the library does, once per model or handle (loading, graph optimisation).
    Info = 3,
    /// Details for diagnosing a problem; frequent.
    Debug = 4,
}

/// A logging callback: `level` is a `ZooLogLevel` value, `message` a NUL-terminated UTF-8 string
/// valid only during the call, `user_data` the pointer given to `zoo_set_log_callback`. It
/// may be called from any thread that calls the library (or a thread of the library), so it
/// must be thread-safe, and it must not call back into the library.
pub type ZooLogCallback = Option<unsafe extern "C" fn(level: i32, message: *const c_char, user_data: *mut c_void)>;

struct Sink {
    callback: unsafe extern "C" fn(i32, *const c_char, *mut c_void),
    user_data: usize,
}

static SINK: RwLock<Option<Sink>> = RwLock::new(None);

struct Forward;

impl log::Log for Forward {
    fn enabled(&self, metadata: &log::Metadata) -> bool {
        metadata.level() <= log::max_level()
    }

    fn log(&self, record: &log::Record) {
        if !self.enabled(record.metadata()) {
            return;
        }
        let Ok(sink) = SINK.read() else { return };
        let Some(sink) = sink.as_ref() else { return };
        let level = match record.level() {
            log::Level::Error => ZooLogLevel::Error,
            log::Level::Warn => ZooLogLevel::Warning,
            log::Level::Info => ZooLogLevel::Info,
            log::Level::Debug | log::Level::Trace => ZooLogLevel::Debug,
        };
        let text = format!("{}: {}", record.target(), record.args()).replace('\0', " ");
        if let Ok(text) = CString::new(text) {
            // SAFETY: the caller of zoo_set_log_callback gives a callback valid for these arguments.
            unsafe { (sink.callback)(level as i32, text.as_ptr(), sink.user_data as *mut c_void) };
        }
    }

    fn flush(&self) {}
}

static FORWARD: Forward = Forward;

/// Sends the library's log messages up to `max_level` (a `ZooLogLevel` value:
/// `ZOO_LOG_LEVEL_WARNING` gives errors and warnings) to `callback`, with `user_data`; a NULL
/// `callback` stops logging (the default: the library logs nothing, and never prints).
/// Messages come from the library and the graph runtime it embeds (tract). Returns
/// `ZOO_STATUS_INVALID_ARGUMENT` for a `max_level` outside `ZooLogLevel`, and
/// `ZOO_STATUS_NOT_AVAILABLE` when the process already has another Rust logger (a Rust host
/// that set its own `log` logger receives the messages there instead). Thread-safe; set it
/// once at start-up.
///
/// Safety: `callback` is NULL or a function valid until it is replaced; `user_data` is what it
/// expects.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn zoo_set_log_callback(
    callback: ZooLogCallback,
    user_data: *mut c_void,
    max_level: i32,
) -> ZooStatus {
    guard("zoo_set_log_callback", || {
        let level = match max_level {
            1 => log::LevelFilter::Error,
            2 => log::LevelFilter::Warn,
            3 => log::LevelFilter::Info,
            4 => log::LevelFilter::Debug,
            v => {
                return Err((
                    ZooStatus::InvalidArgument,
                    format!(
                        "`max_level` is {v}, not a ZooLogLevel; use ZOO_LOG_LEVEL_ERROR (1), ZOO_LOG_LEVEL_WARNING \
                         (2), ZOO_LOG_LEVEL_INFO (3) or ZOO_LOG_LEVEL_DEBUG (4)"
                    ),
                ));
            }
        };
        install_logger()?;
        let mut sink = SINK.write().unwrap_or_else(|e| e.into_inner());
        *sink = callback.map(|callback| Sink { callback, user_data: user_data as usize });
        log::set_max_level(if sink.is_some() { level } else { log::LevelFilter::Off });
        Ok(())
    })
}

/// Makes `Forward` the process's logger, once; an error when another logger was set first.
fn install_logger() -> Result<(), crate::Failure> {
    static INSTALLED: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    let ours = *INSTALLED.get_or_init(|| log::set_logger(&FORWARD).is_ok());
    if ours {
        Ok(())
    } else {
        Err((
            ZooStatus::NotAvailable,
            "the process already has a Rust `log` logger (set by the host), so the library's messages go there; \
             read them from that logger"
                .into(),
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::ffi::CStr;

    #[test]
    fn names_every_status_and_any_other_value() {
        let name = |s: i32| unsafe { CStr::from_ptr(zoo_status_string(s)) }.to_str().unwrap().to_string();
        assert_eq!(name(ZooStatus::Ok as i32), "ZOO_STATUS_OK");
        assert_eq!(name(ZooStatus::InvalidArgument as i32), "ZOO_STATUS_INVALID_ARGUMENT");
        assert_eq!(name(ZooStatus::Panic as i32), "ZOO_STATUS_PANIC");
        for bad in [-1, 9, i32::MAX, i32::MIN] {
            assert_eq!(name(bad), "ZOO_STATUS_UNKNOWN");
        }
        let version = unsafe { CStr::from_ptr(zoo_version_string()) }.to_str().unwrap();
        assert_eq!(version, format!("zoo {} (C ABI {ZOO_ABI_VERSION})", env!("CARGO_PKG_VERSION")));
    }
}
