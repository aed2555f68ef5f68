//! How a run's progress is shown ([`crate::runner::LogMode`]): an indicatif bar on a terminal, a
//! plain line every few seconds when stderr is not one (a Slurm log, a pipe, a file), one JSON
//! object per iteration on stdout, or nothing.
//!
//! The plain line reads `iter 120/2500  loss 0.01234  eta 3m10s`; it is printed for the first
//! iteration of the session, then at most every [`LINE_INTERVAL`], and for the last iteration.
//! The estimate is the mean time per iteration of this session times the iterations left.

use std::io::{IsTerminal, Write};
use std::time::{Duration, Instant};

use stylize::pipeline::IterationRecord;
use stylize::runner::Progress;

use crate::runner::LogMode;

/// The least time between two plain progress lines.
pub const LINE_INTERVAL: Duration = Duration::from_secs(5);

/// The progress display for `mode` (the bar only when stderr is a terminal).
pub fn reporter(mode: LogMode) -> Box<dyn Progress> {
    match mode {
        LogMode::Quiet => Box::new(Quiet),
        LogMode::Jsonl => Box::new(JsonLines),
        LogMode::Bar if std::io::stderr().is_terminal() => Box::new(Bar(None)),
        LogMode::Bar => Box::new(Lines::new(std::io::stderr(), LINE_INTERVAL)),
    }
}

/// The `loss` term of a record (NaN when there is none).
fn loss(record: &IterationRecord) -> f64 {
    record
        .terms
        .iter()
        .find(|(k, _)| *k == "loss")
        .map_or(f64::NAN, |t| t.1)
}

/// Nothing but warnings (which `--quiet` has always printed).
struct Quiet;

impl Progress for Quiet {
    fn warning(&mut self, message: &str) {
        errln!("{message}");
    }
}

/// `metrics.jsonl` lines on stdout. When stdout cannot be written (the reader hung up), the run
/// stops as if signalled ([`crate::signals::output_closed`]): checkpoint, exit 141.
struct JsonLines;

impl Progress for JsonLines {
    fn iteration(&mut self, _record: &IterationRecord, json: &str) {
        if outln!("{json}").is_err() {
            crate::signals::output_closed();
        }
    }

    fn warning(&mut self, message: &str) {
        errln!("{message}");
    }
}

/// An indicatif bar on stderr (a terminal).
struct Bar(Option<indicatif::ProgressBar>);

impl Progress for Bar {
    fn start(&mut self, total: u64, at: u64, headline: &[String]) {
        let bar = indicatif::ProgressBar::new(total);
        let style = indicatif::ProgressStyle::with_template(
            "{bar:30} {pos}/{len} {msg} {per_sec} ETA {eta}",
        )
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar());
        bar.set_style(style);
        bar.set_position(at);
        for line in headline {
            bar.println(line);
        }
        self.0 = Some(bar);
    }

    fn iteration(&mut self, record: &IterationRecord, _json: &str) {
        if let Some(bar) = &self.0 {
            bar.set_position(record.iteration);
            bar.set_message(format!("loss {:.5}", loss(record)));
        }
    }

    fn warning(&mut self, message: &str) {
        match &self.0 {
            Some(bar) => bar.suspend(|| errln!("{message}")),
            None => errln!("{message}"),
        }
    }

    fn finish(&mut self) {
        if let Some(bar) = self.0.take() {
            bar.finish_and_clear();
        }
    }
}

/// Plain progress lines for logs that are not a terminal.
pub struct Lines<W: Write> {
    out: W,
    interval: Duration,
    total: u64,
    /// Iteration the session started at, and when.
    start: Option<(u64, Instant)>,
    last_line: Option<Instant>,
}

impl<W: Write> Lines<W> {
    /// Lines to `out`, at most one per `interval` (besides the first and the last).
    pub fn new(out: W, interval: Duration) -> Self {
        Self {
            out,
            interval,
            total: 0,
            start: None,
            last_line: None,
        }
    }

    /// The sink (tests read what was written).
    pub fn into_inner(self) -> W {
        self.out
    }

    /// [`Progress::start`] at time `now`.
    pub fn start_at(&mut self, total: u64, at: u64, headline: &[String], now: Instant) {
        self.total = total;
        self.start = Some((at, now));
        self.last_line = None;
        for line in headline {
            // A log that cannot be written to is no reason to stop a run.
            let _ = writeln!(self.out, "{line}");
        }
    }

    /// [`Progress::iteration`] at time `now`.
    pub fn iteration_at(&mut self, record: &IterationRecord, now: Instant) {
        let (at, started) = *self.start.get_or_insert((0, now));
        let due = match self.last_line {
            None => true,
            Some(last) => now.duration_since(last) >= self.interval,
        };
        if !(due || record.iteration >= self.total) {
            return;
        }
        self.last_line = Some(now);
        let done = record.iteration.saturating_sub(at);
        let left = self.total.saturating_sub(record.iteration);
        let eta = if done == 0 {
            "?".to_string()
        } else {
            let per = now.duration_since(started).as_secs_f64() / done as f64;
            duration_words(per * left as f64)
        };
        let _ = writeln!(
            self.out,
            "iter {}/{}  loss {:.5}  eta {eta}",
            record.iteration,
            self.total,
            loss(record)
        );
        let _ = self.out.flush();
    }
}

impl<W: Write> Progress for Lines<W> {
    fn start(&mut self, total: u64, at: u64, headline: &[String]) {
        self.start_at(total, at, headline, Instant::now());
    }

    fn iteration(&mut self, record: &IterationRecord, _json: &str) {
        self.iteration_at(record, Instant::now());
    }

    fn warning(&mut self, message: &str) {
        let _ = writeln!(self.out, "{message}");
    }
}

/// `seconds` as `1h02m`, `3m10s` or `12s` (rounded to the second).
fn duration_words(seconds: f64) -> String {
    let s = if seconds.is_finite() && seconds > 0.0 {
        seconds.round() as u64
    } else {
        0
    };
    match (s / 3600, (s % 3600) / 60, s % 60) {
        (0, 0, sec) => format!("{sec}s"),
        (0, m, sec) => format!("{m}m{sec:02}s"),
        (h, m, _) => format!("{h}h{m:02}m"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(iteration: u64, loss: f64) -> IterationRecord {
        IterationRecord {
            iteration,
            terms: vec![("loss", loss)],
            ..IterationRecord::default()
        }
    }

    #[test]
    fn plain_lines_come_first_then_every_interval_then_last_with_an_eta() {
        let t0 = Instant::now();
        let mut lines = Lines::new(Vec::new(), Duration::from_secs(5));
        lines.start_at(10, 2, &["style cube on bunny.obj".to_string()], t0);
        // One iteration per second from iteration 3 on.
        for i in 3..=10 {
            lines.iteration_at(&record(i, 0.5 / i as f64), t0 + Duration::from_secs(i - 2));
        }
        let text = String::from_utf8(lines.into_inner()).expect("utf-8");
        let got: Vec<&str> = text.lines().collect();
        assert_eq!(
            got,
            [
                "style cube on bunny.obj",
                // First line: 1 s for 1 iteration, 7 left.
                "iter 3/10  loss 0.16667  eta 7s",
                // 5 s later.
                "iter 8/10  loss 0.06250  eta 2s",
                // The last iteration, although the interval has not passed.
                "iter 10/10  loss 0.05000  eta 0s",
            ]
        );
    }

    #[test]
    fn durations_read_as_words() {
        assert_eq!(duration_words(12.4), "12s");
        assert_eq!(duration_words(190.0), "3m10s");
        assert_eq!(duration_words(3720.0), "1h02m");
        assert_eq!(duration_words(f64::NAN), "0s");
    }
}
