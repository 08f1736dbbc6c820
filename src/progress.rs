//! Progress of long work: an indicatif bar on a terminal, a plain line every few seconds
//! otherwise (indicatif hides itself when stderr is not a terminal, and CI logs should still
//! show that a fit is alive), or a [`ProgressSink`] the caller of the library provides (the
//! Python package's callback), which may also stop the work.
//!
//! Work that can be stopped takes a [`Reporting`] in its options, starts a [`Progress`] from
//! it per stage and calls [`Progress::step`], which fails once the sink asked to stop.

use crate::error::{Error, Result};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::io::IsTerminal;
use std::sync::Arc;
use std::time::{Duration, Instant};

const PLAIN_INTERVAL: Duration = Duration::from_secs(5);

/// A receiver of progress that the caller of the library provides.
pub trait ProgressSink: Send + Sync {
    /// Stage `stage` has done `done` of `total` steps; `message` is a short note (the current
    /// loss, a sub-stage). Returning `false` asks the work to stop: the next
    /// [`Progress::step`] of any stage fails with [`stopped`].
    fn update(&self, stage: &str, done: u64, total: u64, message: &str) -> bool;
}

/// Where the progress of a run goes.
#[derive(Clone, Default)]
pub enum Reporting {
    /// Nowhere.
    #[default]
    Off,
    /// The terminal's standard error: a bar, or plain lines when it is not a terminal.
    Terminal,
    /// The caller's sink.
    Sink(Arc<dyn ProgressSink>),
}

impl std::fmt::Debug for Reporting {
    fn fmt(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
        f.write_str(match self {
            Reporting::Off => "Off",
            Reporting::Terminal => "Terminal",
            Reporting::Sink(_) => "Sink",
        })
    }
}

impl Reporting {
    /// The terminal's display when `show` (the command line without `--quiet`), else none.
    pub fn terminal_if(show: bool) -> Reporting {
        if show {
            Reporting::Terminal
        } else {
            Reporting::Off
        }
    }

    /// Whether progress goes anywhere.
    pub fn is_on(&self) -> bool {
        !matches!(self, Reporting::Off)
    }

    /// The progress of `total` steps of work called `label`.
    pub fn start(&self, label: &str, total: u64) -> Progress {
        self.start_with_template(label, total, "{pos}/{len} {msg} ({elapsed})")
    }

    /// The progress of `total` items (`unit`, e.g. texels) of work called `label`; the
    /// terminal shows their rate and the time left.
    pub fn start_with_rate(&self, label: &str, total: u64, unit: &str) -> Progress {
        let counts = format!("{{human_pos}}/{{human_len}} {unit} ({{per_sec}}, {{eta}} left)");
        self.start_with_template(label, total, &counts)
    }

    fn start_with_template(&self, label: &str, total: u64, counts: &str) -> Progress {
        let display = match self {
            Reporting::Off => Display::Off,
            Reporting::Sink(sink) => Display::Sink(sink.clone()),
            Reporting::Terminal if std::io::stderr().is_terminal() => {
                let bar = ProgressBar::with_draw_target(Some(total), ProgressDrawTarget::stderr());
                bar.set_style(
                    ProgressStyle::with_template(&format!("{{prefix}} [{{bar:30}}] {counts}"))
                        .expect("valid template")
                        .progress_chars("=> "),
                );
                bar.set_prefix(label.to_string());
                Display::Bar(bar)
            }
            Reporting::Terminal => Display::Plain(Instant::now()),
        };
        Progress {
            display,
            label: label.to_string(),
            total,
            stopped: false,
        }
    }
}

enum Display {
    Off,
    Bar(ProgressBar),
    /// A plain line every [`PLAIN_INTERVAL`]; the time of the last one.
    Plain(Instant),
    Sink(Arc<dyn ProgressSink>),
}

/// The progress of one stage of work.
pub struct Progress {
    display: Display,
    label: String,
    total: u64,
    /// The sink asked to stop.
    stopped: bool,
}

/// The error of work whose progress sink asked it to stop.
pub fn stopped() -> Error {
    Error::argument("progress", "the work was stopped by its progress callback")
}

impl Progress {
    /// A terminal progress display for `total` steps of work called `label`.
    pub fn new(label: &str, total: u64) -> Self {
        Reporting::Terminal.start(label, total)
    }

    /// Reports step `pos` with a short message (e.g. the current loss); an error once the
    /// sink asked to stop ([`stopped`]).
    pub fn step(&mut self, pos: u64, message: impl FnOnce() -> String) -> Result<()> {
        match &mut self.display {
            Display::Off => {}
            Display::Bar(bar) => {
                bar.set_position(pos);
                bar.set_message(message());
            }
            Display::Plain(last) if last.elapsed() >= PLAIN_INTERVAL => {
                eprintln!("{}: step {pos}: {}", self.label, message());
                *last = Instant::now();
            }
            Display::Plain(_) => {}
            Display::Sink(sink) => {
                if !self.stopped && !sink.update(&self.label, pos, self.total, &message()) {
                    self.stopped = true;
                }
            }
        }
        if self.stopped {
            Err(stopped())
        } else {
            Ok(())
        }
    }

    /// Reports step `pos` of work that is not stopped half-way (a terminal display).
    pub fn update(&mut self, pos: u64, message: impl FnOnce() -> String) {
        // Only a sink stops work, and such work calls `step`.
        let _ = self.step(pos, message);
    }

    /// The end of the stage: the bar is cleared, a sink is told every step is done.
    pub fn finish(&self) {
        match &self.display {
            Display::Bar(bar) => bar.finish_and_clear(),
            Display::Sink(sink) if !self.stopped => {
                sink.update(&self.label, self.total, self.total, "done");
            }
            _ => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Mutex;

    /// Records every update and asks to stop after `stop_after` of them.
    struct Recording {
        updates: Mutex<Vec<(String, u64, u64, String)>>,
        stop_after: usize,
    }

    impl ProgressSink for Recording {
        fn update(&self, stage: &str, done: u64, total: u64, message: &str) -> bool {
            let mut updates = self.updates.lock().unwrap();
            updates.push((stage.into(), done, total, message.into()));
            updates.len() < self.stop_after
        }
    }

    #[test]
    fn a_sink_sees_every_step_and_stops_the_work_when_it_asks() {
        let sink = Arc::new(Recording {
            updates: Mutex::default(),
            stop_after: 2,
        });
        let mut progress = Reporting::Sink(sink.clone()).start("fit", 10);
        assert!(progress.step(1, || "a".into()).is_ok());
        let err = progress.step(2, || "b".into()).unwrap_err().to_string();
        assert!(err.contains("stopped by its progress callback"), "{err}");
        // Once stopped, the sink is not called again and every step fails.
        assert!(progress.step(3, || "c".into()).is_err());
        progress.finish();
        let updates = sink.updates.lock().unwrap().clone();
        assert_eq!(
            updates,
            vec![
                ("fit".into(), 1, 10, "a".into()),
                ("fit".into(), 2, 10, "b".into())
            ]
        );
    }

    #[test]
    fn finishing_tells_the_sink_that_every_step_is_done() {
        let sink = Arc::new(Recording {
            updates: Mutex::default(),
            stop_after: usize::MAX,
        });
        let mut progress = Reporting::Sink(sink.clone()).start("maps", 4);
        progress.step(1, String::new).unwrap();
        progress.finish();
        let updates = sink.updates.lock().unwrap().clone();
        assert_eq!(updates.last(), Some(&("maps".into(), 4, 4, "done".into())));
        // Off reports nothing and never stops.
        let mut off = Reporting::Off.start("x", 1);
        assert!(off.step(1, || unreachable!()).is_ok());
    }
}
