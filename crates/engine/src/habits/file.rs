//! The JSON form of a habit model: written by [`HabitModel::to_json`], read and checked by
//! [`HabitModel::from_json`].

use super::*;
use crate::site::Site;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// The JSON form.
#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct ModelFile {
    format: String,
    version: u32,
    site: SiteKey,
    epochs: u64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    learned_through_ns: Option<u64>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    strength: Option<f64>,
    transitions: Vec<RowFile>,
    fix: FixStatistics,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct RowFile {
    from: u32,
    to: Vec<u32>,
    count: Vec<f64>,
}

impl HabitModel {
    /// The model as JSON (`format` `"waymark-habits"`, `version` [`VERSION`]).
    pub fn to_json(&self) -> String {
        let file = ModelFile {
            format: FORMAT.into(),
            version: VERSION,
            site: self.site.clone(),
            epochs: self.epochs,
            learned_through_ns: self.learned_through_ns,
            strength: self.strength,
            transitions: self
                .rows
                .iter()
                .map(|(&from, row)| RowFile {
                    from,
                    to: row.iter().map(|e| e.0).collect(),
                    count: row.iter().map(|e| e.1).collect(),
                })
                .collect(),
            fix: self.fix.clone(),
        };
        serde_json::to_string(&file).unwrap_or_default()
    }

    /// Reads a model exported by [`to_json`](Self::to_json) for `site`, checking every field.
    pub fn from_json(json: &str, site: &Site) -> Result<Self, HabitError> {
        let value: serde_json::Value =
            serde_json::from_str(json).map_err(|e| HabitError::Json(e.to_string()))?;
        let format = value.get("format").and_then(|f| f.as_str()).unwrap_or_default();
        if format != FORMAT {
            return Err(HabitError::Format(format.to_owned()));
        }
        match value.get("version").and_then(serde_json::Value::as_u64) {
            Some(v) if v <= u64::from(VERSION) => {}
            Some(v) => {
                return Err(HabitError::UnsupportedVersion {
                    found: v.min(u64::from(u32::MAX)) as u32,
                    supported: VERSION,
                })
            }
            None => return Err(HabitError::Json("missing field `version`".into())),
        }
        let file: ModelFile = serde_json::from_value(value).map_err(|e| HabitError::Json(e.to_string()))?;
        let key = SiteKey::of(site);
        if file.site.states != key.states || file.site.digest != key.digest {
            return Err(HabitError::WrongSite(format!(
                "learned on {:?} ({} states, digest {}), this is {:?} ({} states, digest {})",
                file.site.name, file.site.states, file.site.digest, key.name, key.states, key.digest
            )));
        }
        let n = key.states as u64;
        let invalid = |path: String, message: String| HabitError::Invalid { path, message };
        let mut rows = BTreeMap::new();
        for (r, row) in file.transitions.into_iter().enumerate() {
            if u64::from(row.from) >= n {
                return Err(invalid(format!("transitions[{r}].from"), format!("state {} of {n}", row.from)));
            }
            if row.to.len() != row.count.len() {
                return Err(invalid(
                    format!("transitions[{r}].count"),
                    format!("{} counts for {} states", row.count.len(), row.to.len()),
                ));
            }
            for (k, (&j, &c)) in row.to.iter().zip(&row.count).enumerate() {
                if u64::from(j) >= n {
                    return Err(invalid(format!("transitions[{r}].to[{k}]"), format!("state {j} of {n}")));
                }
                if k > 0 && row.to[k - 1] >= j {
                    return Err(invalid(format!("transitions[{r}].to[{k}]"), "states must ascend".into()));
                }
                if !(c.is_finite() && (0.0..=MAX_COUNT).contains(&c)) {
                    return Err(invalid(
                        format!("transitions[{r}].count[{k}]"),
                        format!("{c} is not a count"),
                    ));
                }
            }
            let entries: Vec<(u32, f64)> = row.to.into_iter().zip(row.count).collect();
            if rows.insert(row.from, entries).is_some() {
                return Err(invalid(format!("transitions[{r}].from"), format!("state {} twice", row.from)));
            }
        }
        if let Some(k) = file.strength {
            if !(k.is_finite() && k > 0.0 && k <= MAX_COUNT) {
                return Err(invalid("strength".into(), format!("{k} is not a pseudo-count > 0")));
            }
        }
        let f = &file.fix;
        let fix_values =
            [f.fixes, f.weight, f.normalised_square, f.weighted_residual[0], f.weighted_residual[1]];
        if fix_values.iter().any(|v| !(v.is_finite() && v.abs() <= MAX_COUNT))
            || f.fixes < 0.0
            || f.weight < 0.0
            || f.normalised_square < 0.0
        {
            return Err(invalid("fix".into(), "statistics must be finite and not negative".into()));
        }
        Ok(Self {
            site: file.site,
            rows,
            fix: file.fix,
            epochs: file.epochs,
            learned_through_ns: file.learned_through_ns,
            strength: file.strength,
        })
    }
}
