//! The hybrid planners' learned completion backend `net` ([`NetCompletion`]: the network of
//! [`crate::completion_net`] behind [`objview_planners::hybrid::completion::Completion`]) and the
//! three hybrid rows of this crate's registry ([`HYBRID_TABLE`]).
//!
//! Why rows here: `objview-planners` must not depend on Burn, so its hybrid rows know only the
//! `identity` and `oracle` backends (and refuse `net`). The rows of [`HYBRID_TABLE`] are the same
//! planners built with [`objview_planners::hybrid::build_hybrid`] and this crate's `net`
//! constructor ([`net_backend`]), with `completion = net` as the default (the shipped weights are
//! compiled into this crate, so they always exist where these rows do). A program offering the
//! hybrids with `net` registers both tables and lets these rows replace the planners crate's
//! ([`objview_planners::registry::Registry::replace`]), as the CLI does.
//!
//! Parameter `completion_weights`: `builtin` (the shipped `data/weights/completion.safetensors`)
//! or a `.safetensors` file of `objview learn train completion` whose sidecar (same stem, `.json`)
//! gives the network's shape.

use std::path::Path;

use burn::tensor::Device;
use objview_episode::{ExecutionMode, Family};
use objview_geom::hash::fnv1a64;
use objview_planners::hybrid::completion::{
    Completion, CompletionBound, CompletionError, NormalizedInput, NET_PREDICTED_POINTS,
};
use objview_planners::hybrid::{build_hybrid, HybridSettings};
use objview_planners::registry::{settings_json, PlannerEntry};
use serde_json::{json, Value};

use crate::completion_net::{CompletionNet, CompletionShape};
use crate::completion_train::load_completion_weights_bytes;

/// The shipped completion weights (safetensors).
pub const BUILTIN_WEIGHTS: &[u8] = include_bytes!("../../../data/weights/completion.safetensors");
/// The sidecar of [`BUILTIN_WEIGHTS`].
pub const BUILTIN_SIDECAR: &str = include_str!("../../../data/weights/completion.json");

/// The learned completion backend.
pub struct NetCompletion {
    net: CompletionNet,
    device: Device,
    describe: Value,
}

impl NetCompletion {
    /// From safetensors bytes and the sidecar JSON text (which gives `settings.shape`).
    pub fn from_bytes(bytes: &[u8], sidecar: &str, source: &str) -> Result<NetCompletion, String> {
        let side: Value =
            serde_json::from_str(sidecar).map_err(|e| format!("{source}: sidecar is not JSON: {e}"))?;
        let shape: CompletionShape = serde_json::from_value(side["settings"]["shape"].clone())
            .map_err(|e| format!("{source}: sidecar settings.shape: {e}"))?;
        let device = Device::flex();
        let net =
            load_completion_weights_bytes(bytes, &shape, &device).map_err(|e| format!("{source}: {e}"))?;
        let describe = json!({
            "weights": source,
            "weights_fnv1a64": format!("{:016x}", fnv1a64(bytes)),
            "params": shape.params(),
            "shape": shape,
            "deviation": shape.deviation(),
            "trained_on": side.get("data").map(|d| json!({"dataset_command": d["dataset_command"], "objects": d["objects"], "cases": d["cases"]})).unwrap_or(Value::Null),
        });
        Ok(NetCompletion { net, device, describe })
    }

    /// The shipped weights.
    pub fn builtin() -> Result<NetCompletion, String> {
        NetCompletion::from_bytes(BUILTIN_WEIGHTS, BUILTIN_SIDECAR, "builtin")
    }

    /// A weights file and its sidecar (`W.json` next to `W.safetensors`).
    pub fn from_file(path: &Path) -> Result<NetCompletion, String> {
        let bytes = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
        let side = crate::train::sidecar_path(path);
        let text = std::fs::read_to_string(&side)
            .map_err(|e| format!("{}: {e} (the weights' sidecar)", side.display()))?;
        NetCompletion::from_bytes(&bytes, &text, &path.display().to_string())
    }

    /// `builtin` or a file (the `completion_weights` parameter).
    pub fn named(weights: &str) -> Result<NetCompletion, String> {
        if weights == "builtin" {
            NetCompletion::builtin()
        } else {
            NetCompletion::from_file(Path::new(weights))
        }
    }

    /// The network.
    pub fn net(&self) -> &CompletionNet {
        &self.net
    }
}

impl Completion for NetCompletion {
    fn name(&self) -> &'static str {
        "net"
    }
    fn bound(&self) -> CompletionBound {
        CompletionBound::Method
    }
    fn describe(&self) -> Value {
        self.describe.clone()
    }
    fn predict(&mut self, input: &NormalizedInput) -> Result<Vec<[f64; 3]>, CompletionError> {
        let pts: Vec<[f32; 3]> = input.points.iter().map(|p| p.map(|x| x as f32)).collect();
        let out = self.net.predict(&pts, &self.device);
        if out.len() != NET_PREDICTED_POINTS {
            return Err(CompletionError::Backend {
                backend: "net".into(),
                message: format!("the network predicted {} points, not {NET_PREDICTED_POINTS}", out.len()),
            });
        }
        if let Some(i) = out.iter().position(|p| !p.iter().all(|x| x.is_finite())) {
            return Err(CompletionError::Backend {
                backend: "net".into(),
                message: format!("predicted point {i} is not finite"),
            });
        }
        Ok(out.into_iter().map(|p| p.map(|x| x as f64)).collect())
    }
}

/// The `net` constructor handed to the hybrid planners ([`objview_planners::hybrid::NetBackend`]):
/// the weights of `settings.completion_weights`.
pub fn net_backend(settings: &HybridSettings) -> Result<Box<dyn Completion>, String> {
    Ok(Box::new(NetCompletion::named(&settings.completion_weights)?))
}

/// The hybrid planners' settings with this crate's default backend, `net`.
pub fn net_defaults() -> HybridSettings {
    HybridSettings { completion: "net".into(), ..HybridSettings::default() }
}

/// `completion-nbv` with the `net` backend available (and the default).
pub const COMPLETION_NBV_ENTRY: PlannerEntry = PlannerEntry {
    name: "completion-nbv",
    family: Family::Hybrid,
    mode: ExecutionMode::Iterative,
    summary:
        "completion (completion=net|oracle|identity, default net) + next best view by hidden point removal",
    defaults: || settings_json(&net_defaults()),
    build: |s| build_hybrid("completion-nbv", s, net_defaults, Some(net_backend)),
};

/// `completion-scp` with the `net` backend available (and the default).
pub const COMPLETION_SCP_ENTRY: PlannerEntry = PlannerEntry {
    name: "completion-scp",
    family: Family::Hybrid,
    mode: ExecutionMode::SetCoverPlan,
    summary: "completion (completion=net|oracle|identity, default net) + exact set cover of the predicted unseen voxels",
    defaults: || settings_json(&net_defaults()),
    build: |s| build_hybrid("completion-scp", s, net_defaults, Some(net_backend)),
};

/// `completion-mcp` with the `net` backend available (and the default).
pub const COMPLETION_MCP_ENTRY: PlannerEntry = PlannerEntry {
    name: "completion-mcp",
    family: Family::Hybrid,
    mode: ExecutionMode::BudgetedPlan,
    summary: "completion (completion=net|oracle|identity, default net) + exact max coverage with K-1 views",
    defaults: || settings_json(&net_defaults()),
    build: |s| build_hybrid("completion-mcp", s, net_defaults, Some(net_backend)),
};

/// The hybrid rows that replace `objview-planners`' own (same names, family and mode).
pub const HYBRID_TABLE: &[PlannerEntry] = &[COMPLETION_NBV_ENTRY, COMPLETION_SCP_ENTRY, COMPLETION_MCP_ENTRY];

#[cfg(test)]
mod tests {
    use super::*;
    use objview_planners::registry::Registry;

    /// Every hybrid row builds its planner with the shipped `net` by default, agrees with the
    /// planner it builds, builds the same planner from its defaults JSON, and replaces the
    /// planners crate's row of the same name in place.
    #[test]
    fn hybrid_rows_default_to_net_and_replace_the_planners_rows() {
        for row in HYBRID_TABLE {
            let p = row.build_default().unwrap();
            assert_eq!(p.name(), format!("{}[net]", row.name));
            assert_eq!((p.family(), p.execution_mode()), (row.family, row.mode));
            assert_eq!(p.params()["completion_bound"], "method");
            assert_eq!(p.params()["completion_model"]["weights"], "builtin");
            assert!(!p.needs_ground_truth());
            let q = (row.build)((row.defaults)()).unwrap();
            assert_eq!(q.params(), p.params(), "{}", row.name);
        }
        let mut r = Registry::from_tables(&[objview_planners::registry::TABLE, crate::TABLE]).unwrap();
        let names = r.names();
        r.replace(HYBRID_TABLE).unwrap();
        assert_eq!(r.names(), names, "same names, same order");
        assert_eq!(r.by_name("completion-mcp").unwrap().name(), "completion-mcp[net]");
        let oracle =
            r.with_params("completion-nbv", &[("completion".into(), serde_json::json!("oracle"))]).unwrap();
        assert_eq!(oracle.name(), "completion-nbv[oracle]");
        assert!(oracle.needs_ground_truth() && oracle.params().get("completion_model").is_none());
    }
}
