//! Progress of long work: an indicatif bar on a terminal, and a plain line every few seconds
//! otherwise (indicatif hides itself when stderr is not a terminal, and CI logs should still
//! show that a fit is alive).

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::time::{Duration, Instant};

const PLAIN_INTERVAL: Duration = Duration::from_secs(5);

pub struct Progress {
    bar: Option<ProgressBar>,
    label: String,
    last_plain: Instant,
}

impl Progress {
    /// A progress display for `total` steps of work called `label`.
    pub fn new(label: &str, total: u64) -> Self {
        Self::with_template(label, total, "{pos}/{len} {msg} ({elapsed})")
    }

    /// A progress display for `total` items (`unit`, e.g. texels) of work called `label`, with
    /// their rate and the time left.
    pub fn with_rate(label: &str, total: u64, unit: &str) -> Self {
        let counts = format!("{{human_pos}}/{{human_len}} {unit} ({{per_sec}}, {{eta}} left)");
        Self::with_template(label, total, &counts)
    }

    fn with_template(label: &str, total: u64, counts: &str) -> Self {
        let bar = std::io::stderr().is_terminal().then(|| {
            let bar = ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr());
            bar.set_style(
                ProgressStyle::with_template(&format!("{{prefix}} [{{bar:30}}] {counts}"))
                    .expect("valid template")
                    .progress_chars("=> "),
            );
            bar.set_prefix(label.to_string());
            bar
        });
        Progress {
            bar,
            label: label.to_string(),
            last_plain: Instant::now(),
        }
    }

    /// Report step `pos` with a short message (e.g. the current loss).
    pub fn update(&mut self, pos: u64, message: impl FnOnce() -> String) {
        match &self.bar {
            Some(bar) => {
                bar.set_position(pos);
                bar.set_message(message());
            }
            None if self.last_plain.elapsed() >= PLAIN_INTERVAL => {
                eprintln!("{}: step {pos}: {}", self.label, message());
                self.last_plain = Instant::now();
            }
            None => {}
        }
    }

    pub fn finish(&self) {
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }
}
