//! The task identity as this crate sees it: an opaque record, field name → canonical value text,
//! that must be equal for a checkpoint to be continued or a complete run to count as done. The
//! caller decides which fields there are and how their values are computed (for stylize: the
//! mesh's hash, the objective, the result-changing settings — `stylize::identity`); this crate
//! stores the record in `task.json` and in every checkpoint, compares records, and names what
//! differs ([`TaskIdentity::differences`]).

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

/// The identity of a run's task. Stored in `task.json` and in every checkpoint as
/// `{"fields": {NAME: VALUE, …}}` (sorted by name).
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct TaskIdentity {
    /// Field name → canonical value text (sorted).
    pub fields: BTreeMap<String, String>,
}

impl TaskIdentity {
    /// Every field that differs, as `field: was OLD, now NEW` (`self` is the recorded identity,
    /// `now` the new one; an absent field reads `(absent)`, a value longer than 80 characters is
    /// cut with `…`). Empty when equal.
    pub fn differences(&self, now: &TaskIdentity) -> Vec<String> {
        let mut out = Vec::new();
        let absent = "(absent)".to_string();
        for key in self.fields.keys().chain(now.fields.keys()) {
            let (a, b) = (self.fields.get(key), now.fields.get(key));
            if a != b && !out.iter().any(|(k, _): &(String, String)| k == key) {
                let short = |v: Option<&String>| {
                    let v = v.unwrap_or(&absent);
                    if v.chars().count() > 80 {
                        format!("{}…", v.chars().take(80).collect::<String>())
                    } else {
                        v.clone()
                    }
                };
                out.push((
                    key.clone(),
                    format!("{key}: was {}, now {}", short(a), short(b)),
                ));
            }
        }
        out.into_iter().map(|(_, m)| m).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn id(pairs: &[(&str, &str)]) -> TaskIdentity {
        TaskIdentity {
            fields: pairs
                .iter()
                .map(|(k, v)| (k.to_string(), v.to_string()))
                .collect(),
        }
    }

    #[test]
    fn differences_name_each_field_once_with_both_values() {
        let a = id(&[
            ("style", "cube"),
            ("config.run.seed", "0"),
            ("mesh.faces", "4"),
        ]);
        assert!(a.differences(&a).is_empty());
        let long = "x".repeat(90);
        let b = id(&[
            ("style", "octahedron"),
            ("config.run.seed", "0"),
            ("prompt", &long),
        ]);
        let d = a.differences(&b);
        assert_eq!(
            d,
            [
                "mesh.faces: was 4, now (absent)".to_string(),
                "style: was cube, now octahedron".to_string(),
                format!("prompt: was (absent), now {}…", "x".repeat(80)),
            ]
        );
    }

    #[test]
    fn the_record_is_stored_as_sorted_fields() {
        let a = id(&[("style", "cube"), ("mesh.sha256", "ab")]);
        let text = serde_json::to_string(&a).unwrap_or_default();
        assert_eq!(text, r#"{"fields":{"mesh.sha256":"ab","style":"cube"}}"#);
        let back: TaskIdentity = serde_json::from_str(&text).unwrap_or_default();
        assert_eq!(back, a);
    }
}
