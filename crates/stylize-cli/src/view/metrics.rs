//! A run's `metrics.jsonl` as columns for the page's plots.
//!
//! Each line is one JSON object with a numeric `iteration` (see `docs/cli.md`, *Run directory*):
//! loss terms (`loss`, `loss_stage1`, …), `stage2_weight` or `alignment`, `grad_norm`, and the
//! timings under `seconds` (flattened here as `seconds.render`, …). Every numeric field becomes a
//! series named by its (flattened) key; a field missing on a line, or not finite, is `None` there.
//! Lines that are not such objects — a partial last line of a run being written, garbage — are
//! skipped and counted, never an error.

use std::collections::BTreeMap;

use serde::Serialize;

/// Columns of a metrics file.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct MetricsTable {
    /// The `iteration` of each kept line, in file order.
    pub iterations: Vec<f64>,
    /// Series name → one value per kept line (`None` where the line has no finite number).
    pub series: BTreeMap<String, Vec<Option<f64>>>,
    /// Lines skipped (not a JSON object with a finite numeric `iteration`); blank lines excepted.
    pub skipped: usize,
    /// 1-based number of the first skipped line.
    pub first_skipped_line: Option<usize>,
}

impl MetricsTable {
    /// Parses the text of a `metrics.jsonl` (see the module documentation).
    pub fn parse(text: &str) -> Self {
        let mut t = Self::default();
        for (i, line) in text.lines().enumerate() {
            let line = line.trim();
            if line.is_empty() {
                continue;
            }
            let row = serde_json::from_str::<serde_json::Value>(line)
                .ok()
                .and_then(|v| match v {
                    serde_json::Value::Object(m) => Some(m),
                    _ => None,
                });
            let Some(row) = row else {
                t.skip(i + 1);
                continue;
            };
            let Some(iteration) = row
                .get("iteration")
                .and_then(serde_json::Value::as_f64)
                .filter(|x| x.is_finite())
            else {
                t.skip(i + 1);
                continue;
            };
            let k = t.iterations.len();
            t.iterations.push(iteration);
            for (key, value) in &row {
                if key == "iteration" {
                    continue;
                }
                match value {
                    serde_json::Value::Object(inner) => {
                        for (sub, v) in inner {
                            t.set(&format!("{key}.{sub}"), k, v);
                        }
                    }
                    v => t.set(key, k, v),
                }
            }
            for column in t.series.values_mut() {
                column.resize(k + 1, None);
            }
        }
        t
    }

    fn skip(&mut self, line: usize) {
        self.skipped += 1;
        self.first_skipped_line.get_or_insert(line);
    }

    fn set(&mut self, name: &str, row: usize, value: &serde_json::Value) {
        let Some(x) = value.as_f64().filter(|x| x.is_finite()) else {
            return;
        };
        let column = self.series.entry(name.to_string()).or_default();
        column.resize(row, None);
        column.push(Some(x));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn garbage_lines_are_skipped_and_missing_fields_are_none() {
        let text = "{\"iteration\":1,\"loss\":2.0,\"seconds\":{\"total\":0.5}}\n\
                    not json\n\
                    \n\
                    [1,2]\n\
                    {\"loss\":3.0}\n\
                    {\"iteration\":2,\"loss\":1.5,\"stage2_weight\":0.3,\"note\":\"x\"}\n\
                    {\"iteration\":3,\"loss\":null,\"grad_norm\":0.1}\n\
                    {\"iteration\":4,\"lo";
        let t = MetricsTable::parse(text);
        assert_eq!(t.iterations, vec![1.0, 2.0, 3.0]);
        assert_eq!(t.skipped, 4);
        assert_eq!(t.first_skipped_line, Some(2));
        assert_eq!(t.series["loss"], vec![Some(2.0), Some(1.5), None]);
        assert_eq!(t.series["stage2_weight"], vec![None, Some(0.3), None]);
        assert_eq!(t.series["grad_norm"], vec![None, None, Some(0.1)]);
        assert_eq!(t.series["seconds.total"], vec![Some(0.5), None, None]);
        assert!(!t.series.contains_key("note"));
    }
}
