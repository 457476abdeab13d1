//! Progress on the steps that take a while (`build`, `demo`, `emulate`).
//!
//! One [`Progress`] reports a sequence of *stages* (importing the mocap,
//! resampling the grid, the emulated board's frames, …), each a count of
//! steps:
//!
//! - on a terminal (stderr), an indicatif bar: `prefix`, the stage's name,
//!   the bar, `done/total` and the time spent;
//! - otherwise (a pipe, a log, CI), one plain line per stage that took
//!   [`PLAIN_AFTER`] or longer, written when it ends:
//!   `marionette: resampling onto the grid: 7560/7560 in 3.1 s`. Short
//!   stages print nothing, so scripted runs stay quiet.
//!
//! A stage's counter only moves forward: [`Progress::set`] never lowers
//! it, and a new stage starts a new line or bar rather than rewinding the
//! last one. Hold-outs and other repeated stages say which repetition they
//! are through [`Progress::set_prefix`].

use std::cell::RefCell;
use std::io::IsTerminal;
use std::time::{Duration, Instant};

/// A stage shorter than this leaves no plain line.
pub const PLAIN_AFTER: Duration = Duration::from_secs(2);

/// The stage being reported.
struct Stage {
    name: String,
    len: u64,
    pos: u64,
    start: Instant,
}

/// Progress reporting: a bar on a terminal, plain lines otherwise, nothing
/// when not asked to show.
pub struct Progress {
    bar: Option<indicatif::ProgressBar>,
    plain: bool,
    prefix: RefCell<String>,
    stage: RefCell<Option<Stage>>,
}

impl Progress {
    /// Reports on stderr if `show`: a bar when stderr is a terminal, plain
    /// lines otherwise.
    #[must_use]
    pub fn new(show: bool) -> Self {
        Self::with_terminal(show, std::io::stderr().is_terminal())
    }

    /// As [`Progress::new`], saying whether stderr is a terminal.
    fn with_terminal(show: bool, terminal: bool) -> Self {
        let bar = (show && terminal).then(|| {
            let bar = indicatif::ProgressBar::new(0);
            if let Ok(style) = indicatif::ProgressStyle::with_template(
                "{prefix}{msg:>30} [{bar:40}] {pos}/{len} {elapsed}",
            ) {
                bar.set_style(style.progress_chars("=> "));
            }
            bar
        });
        Self {
            bar,
            plain: show && !terminal,
            prefix: RefCell::new(String::new()),
            stage: RefCell::new(None),
        }
    }

    /// Names the repetition the next stages belong to (`"hold-out 2/5: "`);
    /// empty for none.
    pub fn set_prefix(&self, prefix: &str) {
        prefix.clone_into(&mut self.prefix.borrow_mut());
        if let Some(bar) = &self.bar {
            bar.set_prefix(prefix.to_owned());
        }
    }

    /// Ends the current stage and starts one of `len` steps.
    pub fn stage(&self, name: &str, len: usize) {
        self.end_stage();
        let len = len as u64;
        *self.stage.borrow_mut() = Some(Stage {
            name: name.to_owned(),
            len,
            pos: 0,
            start: Instant::now(),
        });
        if let Some(bar) = &self.bar {
            bar.reset();
            bar.set_message(name.to_owned());
            bar.set_length(len);
        }
    }

    /// One step done.
    pub fn tick(&self) {
        let pos = self.stage.borrow().as_ref().map_or(1, |s| s.pos + 1);
        self.set(pos as usize);
    }

    /// `done` steps of the stage are done (never moves the count back).
    pub fn set(&self, done: usize) {
        let mut stage = self.stage.borrow_mut();
        let Some(s) = stage.as_mut() else { return };
        let done = (done as u64).min(s.len);
        if done <= s.pos {
            return;
        }
        s.pos = done;
        if let Some(bar) = &self.bar {
            bar.set_position(done);
        }
    }

    /// Ends the last stage and clears the bar.
    pub fn finish(&self) {
        self.end_stage();
        if let Some(bar) = &self.bar {
            bar.finish_and_clear();
        }
    }

    /// Ends the current stage: its plain line, if it took long enough.
    fn end_stage(&self) {
        let Some(s) = self.stage.borrow_mut().take() else {
            return;
        };
        if self.plain {
            let line = plain_line(
                &self.prefix.borrow(),
                &s.name,
                s.pos,
                s.len,
                s.start.elapsed(),
            );
            if let Some(line) = line {
                eprintln!("{line}");
            }
        }
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        self.finish();
    }
}

/// The plain line for a stage that ended after `took`, `None` if it was
/// shorter than [`PLAIN_AFTER`].
#[must_use]
pub fn plain_line(prefix: &str, name: &str, done: u64, len: u64, took: Duration) -> Option<String> {
    (took >= PLAIN_AFTER).then(|| {
        format!(
            "marionette: {prefix}{name}: {done}/{len} in {:.1} s",
            took.as_secs_f64()
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn short_stages_leave_no_line_and_long_ones_say_what_and_how_long() {
        assert_eq!(
            plain_line("", "resampling", 9, 9, Duration::from_millis(1999)),
            None
        );
        assert_eq!(
            plain_line(
                "hold-out 2/5: ",
                "resampling",
                7,
                9,
                Duration::from_millis(3050)
            )
            .as_deref(),
            Some("marionette: hold-out 2/5: resampling: 7/9 in 3.0 s")
        );
    }

    #[test]
    fn the_count_never_goes_back_nor_past_the_stage() {
        let p = Progress::with_terminal(true, false);
        p.stage("frames", 10);
        p.set(4);
        p.set(2);
        p.tick();
        let pos = |p: &Progress| p.stage.borrow().as_ref().map(|s| s.pos);
        assert_eq!(pos(&p), Some(5));
        p.set(50);
        assert_eq!(pos(&p), Some(10));
        p.stage("next", 3);
        assert_eq!(pos(&p), Some(0));
        p.finish();
        assert_eq!(pos(&p), None);
    }

    #[test]
    fn hidden_progress_draws_nothing() {
        let p = Progress::with_terminal(false, true);
        assert!(p.bar.is_none() && !p.plain);
        let p = Progress::with_terminal(true, true);
        assert!(p.bar.is_some() && !p.plain);
    }
}
