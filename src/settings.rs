//! Settings from nested key–value overrides (JSON objects), for front ends that do not build
//! the Rust structs themselves: the Python package's keyword arguments, configuration files.
//!
//! Every configuration struct of the library is `Serialize + Deserialize`; [`apply`] writes
//! the base settings as JSON, replaces the values the overrides name (objects merge key by
//! key, anything else replaces), and reads the result back. A key the base settings do not
//! have is an [`Error::InvalidConfig`] naming it and the keys that exist; a value of the wrong
//! type is one naming the key. O(size of the settings).

use serde::Serialize;
use serde::de::DeserializeOwned;
use serde_json::Value;

use crate::{Error, Result};

fn merge(base: &mut Value, over: &Value, path: &str) -> Result<()> {
    match (base, over) {
        (Value::Object(b), Value::Object(o)) => {
            for (k, v) in o {
                let key = if path.is_empty() {
                    k.clone()
                } else {
                    format!("{path}.{k}")
                };
                match b.get_mut(k) {
                    Some(slot) => merge(slot, v, &key)?,
                    None => {
                        let mut known: Vec<&str> = b.keys().map(String::as_str).collect();
                        known.sort_unstable();
                        return Err(Error::InvalidConfig {
                            field: "settings",
                            message: format!(
                                "unknown setting `{key}`; the settings{} are: {}",
                                if path.is_empty() {
                                    String::new()
                                } else {
                                    format!(" of `{path}`")
                                },
                                known.join(", ")
                            ),
                        });
                    }
                }
            }
            Ok(())
        }
        (slot, v) => {
            *slot = v.clone();
            Ok(())
        }
    }
}

/// `base` with `overrides` applied (module documentation).
pub fn apply<T: Serialize + DeserializeOwned>(base: &T, overrides: &Value) -> Result<T> {
    let mut value = serde_json::to_value(base).map_err(|e| Error::InvalidConfig {
        field: "settings",
        message: format!("the settings cannot be written as JSON: {e}"),
    })?;
    if !overrides.is_null() {
        merge(&mut value, overrides, "")?;
    }
    serde_json::from_value(value).map_err(|e| Error::InvalidConfig {
        field: "settings",
        message: format!("a setting has the wrong type or value: {e}"),
    })
}

/// The settings as a JSON value (what [`apply`] merges into).
pub fn to_value<T: Serialize>(settings: &T) -> Result<Value> {
    serde_json::to_value(settings).map_err(|e| Error::InvalidConfig {
        field: "settings",
        message: format!("the settings cannot be written as JSON: {e}"),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Config;

    #[test]
    fn defaults_round_trip_and_overrides_apply_by_key() {
        let c = Config::default();
        let same: Config = apply(&c, &Value::Null).unwrap();
        assert_eq!(format!("{same:?}"), format!("{c:?}"));
        let o = serde_json::json!({"camera": "perspective", "completion": {"runs": 3},
                                   "refine": null, "perspective": {"intrinsics": {"focal_px": 800.0}}});
        let c2: Config = apply(&c, &o).unwrap();
        assert_eq!(c2.camera, crate::CameraModel::Perspective);
        assert_eq!(c2.completion.runs, 3);
        assert!(c2.refine.is_none());
        assert_eq!(c2.perspective.intrinsics.focal_px, Some(800.0));
        assert_eq!(c2.completion.max_iterations, c.completion.max_iterations);
        let t = crate::tracking::TrackerConfig::default();
        let t2: crate::tracking::TrackerConfig =
            apply(&t, &serde_json::json!({"klt": {"window": 15}})).unwrap();
        assert_eq!(t2.klt.window, 15);
    }

    #[test]
    fn unknown_keys_and_wrong_types_are_named() {
        let c = Config::default();
        let e = apply(&c, &serde_json::json!({"completion": {"rnus": 3}})).unwrap_err();
        assert!(e.to_string().contains("`completion.rnus`"), "{e}");
        assert!(e.to_string().contains("runs"), "{e}");
        let e = apply(&c, &serde_json::json!({"seed": "zero"})).unwrap_err();
        assert!(matches!(e, Error::InvalidConfig { .. }), "{e}");
    }
}
