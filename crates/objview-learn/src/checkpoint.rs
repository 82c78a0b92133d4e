//! The training loops' shared file plumbing (NBV-Net in [`crate::train`], MA-SCVP in
//! [`crate::mascvp_train`], the completion network in [`crate::completion_train`]): reproducible safetensors weights, and per-epoch checkpoints that let
//! `--resume` continue a run exactly where it stopped.
//!
//! A run writing `W.safetensors` keeps `W.safetensors.checkpoints/`: per epoch k the evaluation
//! weights `epoch-k.safetensors` (what selection copies to `W`), the training module
//! `epoch-k.bpk` (Burnpack keeps the parameter ids the optimizer state is keyed by) and the
//! optimizer state `epoch-k.optim`; and `state.json` = the run's *identity* (the settings that
//! shape the trajectory, the data, anything else the caller names) and the epoch history. A resume
//! with another identity is refused rather than silently mixing runs.

use std::path::{Path, PathBuf};

use burn::module::Module;
use burn::optim::{ModuleOptimizer, OptimizerRecord};
use burn::store::{BurnpackStore, ModuleSnapshot, SafetensorsStore};
use serde::de::DeserializeOwned;
use serde::Serialize;
use serde_json::{json, Value};

use crate::LearnError;

/// The checkpoint folder of a run writing `out` (`out` + `.checkpoints`).
pub fn checkpoint_dir(out: &Path) -> PathBuf {
    let mut s = out.as_os_str().to_owned();
    s.push(".checkpoints");
    PathBuf::from(s)
}

/// Saves `net` as safetensors at `path`. One metadata key: burn's default metadata is a
/// HashMap, whose order (and so the file's bytes) would change from run to run.
pub fn save_safetensors<M: Module>(net: &M, path: &Path) -> Result<(), LearnError> {
    let mut store = SafetensorsStore::from_file(path)
        .clear_metadata()
        .metadata("producer", "objview (burn 0.22.1)")
        .overwrite(true);
    net.save_into(&mut store).map_err(|e| LearnError::io(path, format!("cannot save weights: {e:?}")))
}

/// Loads safetensors `bytes` into `net`; every tensor must be present and fit (`what` names
/// the network in the error).
pub fn load_safetensors<M: Module>(net: &mut M, bytes: &[u8], what: &str) -> Result<(), String> {
    let mut store = SafetensorsStore::from_bytes(Some(bytes.to_vec()));
    let r = net.load_from(&mut store).map_err(|e| format!("cannot load weights: {e:?}"))?;
    if !r.errors.is_empty() || !r.missing.is_empty() {
        return Err(format!("weights do not fit {what}: missing {:?}, errors {:?}", r.missing, r.errors));
    }
    Ok(())
}

/// The checkpoints of one training run.
#[derive(Debug, Clone)]
pub struct Checkpoints {
    dir: PathBuf,
    state: PathBuf,
    identity: Value,
}

impl Checkpoints {
    /// The checkpoints of a run writing `out` whose trajectory is fixed by `identity` (creates
    /// the folder).
    pub fn create(out: &Path, identity: Value) -> Result<Checkpoints, LearnError> {
        let dir = checkpoint_dir(out);
        std::fs::create_dir_all(&dir).map_err(|e| LearnError::io(&dir, e))?;
        Ok(Checkpoints { state: dir.join("state.json"), dir, identity })
    }

    /// The evaluation weights of `epoch` (1-based).
    pub fn weights(&self, epoch: usize) -> PathBuf {
        self.dir.join(format!("epoch-{epoch}.safetensors"))
    }

    /// Continues an earlier run: its history (cut to `epochs`) and, when it stopped before
    /// `epochs`, its last epoch's module loaded into `net` and its optimizer state returned (for
    /// `optim.load_record`). Nothing to resume: an empty history. Another identity: an error
    /// naming the state file.
    pub fn resume<H: DeserializeOwned, M: Module>(
        &self,
        epochs: usize,
        net: &mut M,
    ) -> Result<(Vec<H>, Option<OptimizerRecord>), LearnError> {
        if !self.state.is_file() {
            return Ok((Vec::new(), None));
        }
        let p = &self.state;
        let text = std::fs::read_to_string(p).map_err(|e| LearnError::io(p, e))?;
        let st: Value = serde_json::from_str(&text).map_err(|e| LearnError::io(p, e))?;
        if st["identity"] != self.identity {
            return Err(LearnError::Invalid(format!(
                "{}: the checkpoint was made with other settings or data; remove the folder or drop --resume",
                p.display()
            )));
        }
        let mut history: Vec<H> =
            serde_json::from_value(st["history"].clone()).map_err(|e| LearnError::io(p, e))?;
        history.truncate(epochs);
        let k = history.len();
        if k > 0 && k < epochs {
            let w = self.dir.join(format!("epoch-{k}.bpk"));
            net.load_from(&mut BurnpackStore::from_file(&w))
                .map_err(|e| LearnError::io(&w, format!("{e:?}")))?;
            let o = self.dir.join(format!("epoch-{k}.optim"));
            let rec = OptimizerRecord::load(&o).map_err(|e| LearnError::io(&o, format!("{e:?}")))?;
            return Ok((history, Some(rec)));
        }
        Ok((history, None))
    }

    /// Records finished `epoch`: the evaluation weights `valid`, the training module `net`, the
    /// optimizer state and the history so far.
    pub fn save<H: Serialize, M: Module, V: Module>(
        &self,
        epoch: usize,
        valid: &V,
        net: &M,
        optim: &ModuleOptimizer,
        history: &[H],
    ) -> Result<(), LearnError> {
        save_safetensors(valid, &self.weights(epoch))?;
        let bpk = self.dir.join(format!("epoch-{epoch}.bpk"));
        net.save_into(&mut BurnpackStore::from_file(&bpk).overwrite(true))
            .map_err(|e| LearnError::io(&bpk, format!("cannot save the checkpoint: {e:?}")))?;
        let o = self.dir.join(format!("epoch-{epoch}.optim"));
        optim.to_record().save(&o).map_err(|e| LearnError::io(&o, format!("{e:?}")))?;
        let st = json!({"identity": self.identity, "history": history});
        std::fs::write(&self.state, serde_json::to_string_pretty(&st).expect("json"))
            .map_err(|e| LearnError::io(&self.state, e))
    }

    /// Copies the weights of `epoch` to `out` (the kept epoch).
    pub fn keep(&self, epoch: usize, out: &Path) -> Result<(), LearnError> {
        std::fs::copy(self.weights(epoch), out).map(|_| ()).map_err(|e| LearnError::io(out, e))
    }
}

/// `settings` (an object) without the keys that do not change a run's trajectory (e.g. the
/// epoch count, which only extends it, and the selection rule).
pub fn trajectory_settings(settings: &Value, ignored: &[&str]) -> Value {
    let mut v = settings.clone();
    if let Some(m) = v.as_object_mut() {
        for k in ignored {
            m.remove(*k);
        }
    }
    v
}
