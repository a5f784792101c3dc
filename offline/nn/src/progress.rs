//! [`Progress`] shown on the terminal: [`Bar`], a spinner for stages and a bar for counted
//! work; [`Stderr`], notices only.

use indicatif::{ProgressBar, ProgressStyle};
use std::sync::Mutex;
use std::time::Duration;
use zoo_data::Progress;

/// A spinner that turns into a bar when counted work starts (a new one after a finish).
pub struct Bar(Mutex<ProgressBar>);

fn spinner() -> ProgressBar {
    let pb = ProgressBar::new_spinner();
    pb.set_style(ProgressStyle::with_template("{spinner} {msg} [{elapsed}]").expect("a valid template"));
    pb.enable_steady_tick(Duration::from_millis(120));
    pb
}

impl Bar {
    /// A spinner, ticking.
    pub fn new() -> Bar {
        Bar(Mutex::new(spinner()))
    }

    /// The bar shown now (a fresh spinner when the last one finished).
    fn current(&self) -> ProgressBar {
        let mut pb = self.0.lock().unwrap_or_else(|e| e.into_inner());
        if pb.is_finished() {
            *pb = spinner();
        }
        pb.clone()
    }
}

impl Progress for Bar {
    fn stage(&self, message: &str) {
        self.current().set_message(message.to_string());
    }

    fn start(&self, total: u64, message: &str) {
        let pb = self.current();
        pb.disable_steady_tick();
        let style = ProgressStyle::with_template("{msg} [{bar:40}] {pos}/{len} [{elapsed}<{eta}]");
        pb.set_style(style.expect("a valid template"));
        pb.set_length(total);
        pb.set_position(0);
        pb.set_message(message.to_string());
    }

    fn advance(&self, units: u64) {
        self.current().inc(units);
    }

    fn note(&self, message: &str) {
        self.current().set_message(message.to_string());
    }

    fn finish(&self) {
        self.current().finish_and_clear();
    }

    fn notice(&self, message: &str) {
        self.current().suspend(|| eprintln!("{message}"));
    }
}

impl Drop for Bar {
    fn drop(&mut self) {
        self.0.lock().unwrap_or_else(|e| e.into_inner()).finish_and_clear();
    }
}

/// Notices on standard error, no progress shown.
pub struct Stderr;

impl Progress for Stderr {
    fn notice(&self, message: &str) {
        eprintln!("{message}");
    }
}
