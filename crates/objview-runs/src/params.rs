//! Planner parameters given as `NAME=VALUE` text (`objview run --param gamma=0.5`): VALUE is
//! JSON where it parses as JSON (numbers, booleans, arrays), else a bare string. Dotted names
//! reach nested settings; the planner registry applies them.

use serde_json::Value;

use crate::RunError;

/// Planner parameters: `(name, value)` pairs in the order given.
pub type Params = Vec<(String, Value)>;

/// Parses `NAME=VALUE` pairs.
pub fn parse_params(raw: &[String]) -> Result<Params, RunError> {
    raw.iter()
        .map(|p| {
            let (k, v) = p
                .split_once('=')
                .ok_or_else(|| RunError::Invalid(format!("--param {p:?}: expected NAME=VALUE")))?;
            let value = serde_json::from_str(v).unwrap_or_else(|_| Value::String(v.to_string()));
            Ok((k.trim().to_string(), value))
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn values_are_json_where_they_parse_and_strings_otherwise() {
        let p = parse_params(&["gamma=0.5".into(), "occupancy.resolution = 32".into(), "mode=fast".into()])
            .unwrap();
        assert_eq!(
            p,
            vec![
                ("gamma".to_string(), json!(0.5)),
                ("occupancy.resolution".to_string(), json!(32)),
                ("mode".to_string(), json!("fast")),
            ]
        );
        assert!(parse_params(&["gamma".into()]).unwrap_err().to_string().contains("expected NAME=VALUE"));
    }
}
