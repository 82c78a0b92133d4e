//! Provenance block written into every output file: the tool, its version and the settings that
//! produced the file, so that results can be traced and compared. Deliberately free of clocks
//! and host names: the same inputs give byte-identical outputs.

use serde_json::{json, Value};

/// `{"tool": "objview", "version": ..., "command": ..., ...settings}`.
pub fn settings(command: &str, settings: Value) -> Value {
    let mut v = json!({
        "tool": "objview",
        "version": env!("CARGO_PKG_VERSION"),
        "command": command,
    });
    if let (Some(m), Value::Object(s)) = (v.as_object_mut(), settings) {
        m.extend(s);
    }
    v
}
