//! The weight-schedule grammar of spec §5, e.g. the stage-II weight `"0.0>0.2:1000; 0.2>0.3:750"`.
//!
//! ```text
//! schedule := phase (';' phase)*
//! phase    := value [':' iterations]          constant
//!           | value '>' value ':' iterations  linear ramp (':N' required)
//! ```
//! Whitespace around tokens is ignored. Iterations are **1-indexed**: the first phase starts at
//! iteration 1. A ramp `A>B:N` starting at iteration `s` has the value `A + (B − A)(k − 1)/(N − 1)`
//! at its `k`-th iteration (`k = i − s + 1`), so it starts exactly at `A` and ends exactly at `B`.
//! A constant phase without `:N` lasts forever (and must therefore be the last phase). After the
//! last phase its end value holds.

use std::fmt;

/// One phase of a [`Schedule`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Phase {
    /// A constant value for `iterations` iterations (`None`: forever).
    Constant {
        /// The value.
        value: f64,
        /// Length in iterations; `None` means unbounded.
        iterations: Option<u64>,
    },
    /// A linear ramp from `from` (first iteration) to `to` (last iteration).
    Ramp {
        /// Value at the first iteration of the phase.
        from: f64,
        /// Value at the last iteration of the phase.
        to: f64,
        /// Length in iterations (≥ 2).
        iterations: u64,
    },
}

impl Phase {
    fn end_value(&self) -> f64 {
        match *self {
            Phase::Constant { value, .. } => value,
            Phase::Ramp { to, .. } => to,
        }
    }
}

/// A parsed schedule; evaluate it with [`Schedule::at`].
#[derive(Clone, Debug, PartialEq)]
pub struct Schedule {
    source: String,
    phases: Vec<Phase>,
}

/// A malformed schedule string: where (0-based character column) and what was expected.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("invalid schedule {text:?} at column {column}: {message}")]
pub struct ScheduleError {
    /// The string being parsed.
    pub text: String,
    /// 0-based character column of the problem.
    pub column: usize,
    /// What was expected or what is wrong.
    pub message: String,
}

impl Schedule {
    /// Parses a schedule string (see the module docs for the grammar).
    pub fn parse(text: &str) -> Result<Self, ScheduleError> {
        Parser {
            src: text,
            chars: text.chars().collect(),
            pos: 0,
        }
        .schedule()
    }

    /// A schedule that is `value` forever.
    pub fn constant(value: f64) -> Self {
        Self {
            source: format!("{value}"),
            phases: vec![Phase::Constant {
                value,
                iterations: None,
            }],
        }
    }

    /// The phases in order.
    pub fn phases(&self) -> &[Phase] {
        &self.phases
    }

    /// The string this schedule was parsed from.
    pub fn source(&self) -> &str {
        &self.source
    }

    /// Value at the 1-indexed `iteration` (iteration 0 is treated as 1).
    pub fn at(&self, iteration: u64) -> f64 {
        let mut start = 1_u64; // first iteration of the current phase
        let i = iteration.max(1);
        for phase in &self.phases {
            match *phase {
                Phase::Constant {
                    value,
                    iterations: None,
                } => return value,
                Phase::Constant {
                    value,
                    iterations: Some(n),
                } => {
                    if i < start + n {
                        return value;
                    }
                    start += n;
                }
                Phase::Ramp {
                    from,
                    to,
                    iterations: n,
                } => {
                    if i < start + n {
                        let k = (i - start) as f64; // k − 1 in the 1-indexed formula
                        return from + (to - from) * k / (n - 1) as f64;
                    }
                    start += n;
                }
            }
        }
        self.phases.last().map_or(0.0, Phase::end_value)
    }
}

impl fmt::Display for Schedule {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.source)
    }
}

impl std::str::FromStr for Schedule {
    type Err = ScheduleError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Self::parse(s)
    }
}

struct Parser<'a> {
    src: &'a str,
    chars: Vec<char>,
    pos: usize,
}

impl Parser<'_> {
    fn err<T>(&self, column: usize, message: impl Into<String>) -> Result<T, ScheduleError> {
        Err(ScheduleError {
            text: self.src.to_string(),
            column,
            message: message.into(),
        })
    }

    fn skip_ws(&mut self) {
        while self.chars.get(self.pos).is_some_and(|c| c.is_whitespace()) {
            self.pos += 1;
        }
    }

    fn peek(&self) -> Option<char> {
        self.chars.get(self.pos).copied()
    }

    fn describe(&self) -> String {
        match self.peek() {
            Some(c) => format!("found {c:?}"),
            None => "found the end of the string".to_string(),
        }
    }

    /// A token: maximal run of characters that are not separators.
    fn token(&mut self) -> (usize, String) {
        self.skip_ws();
        let start = self.pos;
        while let Some(c) = self.peek() {
            if c == ';' || c == '>' || c == ':' || c.is_whitespace() {
                break;
            }
            self.pos += 1;
        }
        (start, self.chars[start..self.pos].iter().collect())
    }

    fn number(&mut self) -> Result<f64, ScheduleError> {
        let (start, tok) = self.token();
        if tok.is_empty() {
            return self.err(start, format!("expected a number, {}", self.describe()));
        }
        match tok.parse::<f64>() {
            Ok(v) if v.is_finite() => Ok(v),
            Ok(_) => self.err(start, format!("expected a finite number, found {tok:?}")),
            Err(_) => self.err(start, format!("expected a number, found {tok:?}")),
        }
    }

    fn count(&mut self) -> Result<(usize, u64), ScheduleError> {
        let (start, tok) = self.token();
        if tok.is_empty() {
            return self.err(
                start,
                format!("expected an iteration count after ':', {}", self.describe()),
            );
        }
        match tok.parse::<u64>() {
            Ok(0) => self.err(start, "an iteration count must be at least 1"),
            Ok(n) => Ok((start, n)),
            Err(_) => self.err(
                start,
                format!("expected a positive integer iteration count, found {tok:?}"),
            ),
        }
    }

    fn phase(&mut self) -> Result<Phase, ScheduleError> {
        self.skip_ws();
        let phase_start = self.pos;
        let from = self.number()?;
        self.skip_ws();
        let to = if self.peek() == Some('>') {
            self.pos += 1;
            Some(self.number()?)
        } else {
            None
        };
        self.skip_ws();
        let iterations = if self.peek() == Some(':') {
            self.pos += 1;
            Some(self.count()?)
        } else {
            None
        };
        self.skip_ws();
        if let Some(c) = self.peek().filter(|&c| c != ';') {
            return self.err(
                self.pos,
                format!("expected ';', '>', ':' or the end, found {c:?}"),
            );
        }
        match (to, iterations) {
            (None, n) => Ok(Phase::Constant {
                value: from,
                iterations: n.map(|(_, n)| n),
            }),
            (Some(_), None) => self.err(
                phase_start,
                "a ramp 'A>B' needs an iteration count ':N' (only constants may last forever)",
            ),
            (Some(_), Some((col, 1))) => self.err(
                col,
                "a ramp needs at least 2 iterations (use a constant for 1)",
            ),
            (Some(to), Some((_, n))) => Ok(Phase::Ramp {
                from,
                to,
                iterations: n,
            }),
        }
    }

    fn schedule(mut self) -> Result<Schedule, ScheduleError> {
        let mut phases = Vec::new();
        loop {
            self.skip_ws();
            let start = self.pos;
            let phase = self.phase()?;
            if let Some(Phase::Constant {
                iterations: None, ..
            }) = phases.last()
            {
                return self.err(
                    start,
                    "unreachable phase: the previous constant has no ':N' and lasts forever",
                );
            }
            phases.push(phase);
            match self.peek() {
                Some(';') => self.pos += 1,
                None => break,
                Some(c) => {
                    return self.err(self.pos, format!("expected ';' or the end, found {c:?}"));
                }
            }
        }
        Ok(Schedule {
            source: self.src.to_string(),
            phases,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> Schedule {
        Schedule::parse(s).unwrap_or_else(|e| panic!("{e}"))
    }

    #[test]
    fn default_stage2_schedule_matches_spec_check_values() {
        let s = parse("0.0>0.2:1000; 0.2>0.3:750");
        let close = |a: f64, b: f64, tol: f64| (a - b).abs() <= tol;
        assert_eq!(s.at(1), 0.0);
        assert!(close(s.at(2), 2.002e-4, 5e-8), "{}", s.at(2));
        assert!(close(s.at(500), 0.0999, 5e-5), "{}", s.at(500));
        assert!(close(s.at(1500), 0.26662, 5e-6), "{}", s.at(1500));
        assert!(close(s.at(2000), 0.3, 1e-15), "{}", s.at(2000));
    }

    #[test]
    fn ramps_start_and_end_exactly_at_their_values() {
        let s = parse("0.0>0.2:1000; 0.2>0.3:750");
        assert_eq!(s.at(1000), 0.2);
        assert_eq!(s.at(1001), 0.2);
        assert!((s.at(1750) - 0.3).abs() < 1e-15);
        assert!((s.at(1751) - 0.3).abs() < 1e-15);
        assert!((s.at(u64::MAX) - 0.3).abs() < 1e-15);
    }

    #[test]
    fn constant_without_length_lasts_forever() {
        let s = parse(" 1.5 ");
        assert_eq!(s.at(1), 1.5);
        assert_eq!(s.at(1_000_000), 1.5);
        let s = parse("2:3; 0.5");
        assert_eq!((s.at(3), s.at(4), s.at(99)), (2.0, 0.5, 0.5));
    }

    #[test]
    fn end_value_holds_after_last_phase() {
        let s = parse("1:2;3>5:3");
        let v: Vec<f64> = (1..=7).map(|i| s.at(i)).collect();
        assert_eq!(v, vec![1.0, 1.0, 3.0, 4.0, 5.0, 5.0, 5.0]);
    }

    #[test]
    fn malformed_strings_report_position_and_expectation() {
        let cases: &[(&str, usize, &str)] = &[
            ("", 0, "expected a number"),
            ("0.0>", 4, "expected a number"),
            ("0.0>0.2", 0, "needs an iteration count"),
            ("0.0>0.2:abc", 8, "positive integer"),
            ("0.0>0.2:0", 8, "at least 1"),
            ("0.0>0.2:1", 8, "at least 2"),
            ("0.0>0.2:10;", 11, "expected a number"),
            ("x", 0, "expected a number, found \"x\""),
            ("1 2", 2, "expected ';'"),
            ("0.5; 1", 5, "unreachable"),
            ("inf", 0, "finite"),
            ("1:", 2, "iteration count"),
        ];
        for &(src, column, needle) in cases {
            match Schedule::parse(src) {
                Ok(s) => panic!("{src:?} parsed as {s:?}"),
                Err(e) => {
                    assert_eq!(e.column, column, "{src:?}: {e}");
                    assert!(e.to_string().contains(needle), "{src:?}: {e}");
                }
            }
        }
    }

    #[test]
    fn iteration_zero_is_treated_as_the_first() {
        let s = parse("0.0>1.0:11");
        assert_eq!(s.at(0), s.at(1));
        assert!((s.at(6) - 0.5).abs() < 1e-15);
    }
}
