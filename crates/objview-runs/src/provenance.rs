//! The provenance block written into every output file: the tool, its version and the settings
//! that produced the file, so that results can be traced and compared. Deliberately free of
//! clocks and host names: the same inputs give byte-identical outputs.

use serde_json::{json, Value};

/// The objview version recorded in outputs.
pub const VERSION: &str = env!("CARGO_PKG_VERSION");

/// `{"tool": "objview", "version": ..., "command": ..., ...settings}` (the keys of an object
/// `settings` are merged in; anything else is ignored).
pub fn settings(command: &str, settings: Value) -> Value {
    let mut v = json!({
        "tool": "objview",
        "version": VERSION,
        "command": command,
    });
    if let (Some(m), Value::Object(s)) = (v.as_object_mut(), settings) {
        m.extend(s);
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_block_names_tool_version_and_command_before_the_settings() {
        let v = settings("pool split", json!({"seed": 3}));
        assert_eq!(v, json!({"tool": "objview", "version": VERSION, "command": "pool split", "seed": 3}));
        assert_eq!(settings("x", json!(5))["command"], "x");
    }
}
