//! A batch of difficulty annotations (SPEC §4): one JSON line per object
//! ([`objview_dataset::annotate`]), resumable (objects already in the results file are skipped)
//! and shardable (`--shard I/N`, by a hash of the uid).

use std::path::PathBuf;
use std::time::Instant;

use objview_dataset::annotate::{annotate_item, AnnotateSettings, GridViews};
use objview_dataset::{drive, resolve_inputs, BatchSummary, Progress, ResumableJsonl, Shard};

use crate::RunError;

/// One annotation batch, fully resolved.
#[derive(Debug, Clone)]
pub struct AnnotatePlan {
    /// Mesh files, folders or split files.
    pub inputs: Vec<PathBuf>,
    /// The results file (JSON Lines).
    pub out: PathBuf,
    /// Every annotation setting.
    pub settings: AnnotateSettings,
    /// Worker threads (`None`: every core).
    pub threads: Option<usize>,
    /// The part of the inputs to annotate.
    pub shard: Shard,
    /// Redo objects whose earlier line is a failure.
    pub retry_failed: bool,
}

impl AnnotatePlan {
    /// A plan with the SPEC's settings over `inputs` into `out`: every object, every core.
    pub fn new(inputs: Vec<PathBuf>, out: PathBuf) -> AnnotatePlan {
        AnnotatePlan {
            inputs,
            out,
            settings: AnnotateSettings::default(),
            threads: None,
            shard: Shard::ALL,
            retry_failed: false,
        }
    }

    /// The settings block of every line: provenance, settings and the shard.
    pub fn settings_json(&self) -> serde_json::Value {
        let mut v = crate::provenance::settings("annotate", self.settings.to_json());
        v["shard"] = serde_json::json!(self.shard.to_string());
        v
    }

    /// Annotates every object of the plan's shard that its results file does not hold yet.
    pub fn run(&self, progress: &dyn Progress) -> Result<(BatchSummary, f64), RunError> {
        self.settings.validate()?;
        if let Some(dir) = &self.settings.gt_cloud_dir {
            if !dir.is_dir() {
                return Err(RunError::Invalid(format!("{}: --gt-cloud-dir is not a folder", dir.display())));
            }
        }
        let objects = self.shard.select(resolve_inputs(&self.inputs)?);
        let views = GridViews::new(self.settings.view_radius)?;
        let settings_json = self.settings_json();
        let (out, existing) = ResumableJsonl::open(&self.out, "uid", self.retry_failed)?;
        let t = Instant::now();
        let summary = drive(
            "annotate",
            Some(format!("shard {}", self.shard)),
            Some(format!("{} views per object", views.total_views())),
            &objects,
            out,
            &existing,
            self.threads,
            |obj| annotate_item(obj, &self.settings, &views, &settings_json),
            progress,
        )?;
        Ok((summary, t.elapsed().as_secs_f64()))
    }
}
