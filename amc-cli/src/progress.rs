//! Progress on the terminal: a bar with frames, frames/s and the time left.
//! Hidden when stderr is not a terminal (logs, pipes, tests).

use amc_engine::Progress;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::sync::Mutex;

/// One bar.
pub struct Bar {
    bar: ProgressBar,
}

impl Bar {
    /// A bar labelled `label`, drawn only when `enabled` and stderr is a terminal.
    pub fn new(label: &str, enabled: bool) -> Self {
        let bar = ProgressBar::new_spinner();
        if !enabled || !std::io::stderr().is_terminal() {
            bar.set_draw_target(ProgressDrawTarget::hidden());
        }
        let style = ProgressStyle::with_template(
            "{prefix:>10} [{bar:30}] {pos}/{len} frames, {per_sec:.0} ({eta} left)",
        )
        .unwrap_or_else(|_| ProgressStyle::default_bar())
        .with_key(
            "per_sec",
            |s: &indicatif::ProgressState, w: &mut dyn std::fmt::Write| {
                let _ = write!(w, "{:.1} frames/s", s.per_sec());
            },
        )
        .progress_chars("=> ");
        bar.set_style(style);
        bar.set_prefix(label.to_string());
        Self { bar }
    }

    /// Shows a run's progress.
    pub fn update(&self, p: Progress) {
        self.count(p.done, p.total.unwrap_or(0));
    }

    /// Shows `done` of `total` (0: unknown).
    pub fn count(&self, done: u64, total: u64) {
        if total > 0 && self.bar.length() != Some(total.max(done)) {
            self.bar.set_length(total.max(done));
        }
        self.bar.set_position(done);
    }

    /// Removes the bar.
    pub fn finish(&self) {
        self.bar.finish_and_clear();
    }
}

/// One bar per mode, for `amc eval`'s consecutive runs.
pub struct Bars {
    enabled: bool,
    current: Mutex<Option<(amc_core::Mode, Bar)>>,
}

impl Bars {
    /// No bar yet.
    pub fn new(enabled: bool) -> Self {
        Self {
            enabled,
            current: Mutex::new(None),
        }
    }

    /// Shows the progress of the run of `mode`, starting its bar if new.
    pub fn update(&self, mode: amc_core::Mode, p: Progress) {
        let mut cur = self.current.lock().unwrap_or_else(|e| e.into_inner());
        if cur.as_ref().map(|(m, _)| *m) != Some(mode) {
            if let Some((_, old)) = cur.take() {
                old.finish();
            }
            *cur = Some((mode, Bar::new(&mode.to_string(), self.enabled)));
        }
        if let Some((_, bar)) = cur.as_ref() {
            bar.update(p);
        }
    }

    /// Removes the last bar.
    pub fn finish(&self) {
        if let Some((_, bar)) = self
            .current
            .lock()
            .unwrap_or_else(|e| e.into_inner())
            .take()
        {
            bar.finish();
        }
    }
}
