//! The machine a benchmark ran on: CPU model, logical CPUs, and the x86 SIMD features that the
//! hot paths select at run time. Every `objview bench` prints it as its first line and records
//! it in its `--json`, because timings only compare on the same kind of CPU: on 2026-12-05 the
//! same build rendered the 98k-triangle `mug` in 3.4 ms on an AMD EPYC VM and in ~1.9 ms on an
//! Intel one, until the renderer stopped using masked stores (`docs/performance.md`, "Masked stores on AMD").
//! Benchmark figures are wall-clock measurements and never byte-identical, so naming the host
//! here costs no reproducibility (the result files of runs and annotations stay host-free).

use serde_json::{json, Value};

/// Largest part of `/proc/cpuinfo` read (the first processor's block is at its start).
const CPUINFO_CAP: u64 = 1 << 16;

/// The benchmark host.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Host {
    /// CPU model name (`/proc/cpuinfo`'s first `model name`), or `unknown`.
    pub cpu: String,
    /// Logical CPUs available to this process.
    pub logical_cpus: usize,
    /// The run-time-detected x86 features that objview's hot paths select on (`avx2`, `popcnt`)
    /// or that bear on their speed (`fma`, `avx512f`), in that order; empty elsewhere.
    pub features: Vec<&'static str>,
    /// The instruction-set baseline the binary was compiled for ([`crate::cpu::build_baseline`]:
    /// `x86-64-v2` unless `RUSTFLAGS` replaced the workspace's flags).
    pub build: &'static str,
}

impl Host {
    /// The host this process runs on.
    pub fn detect() -> Host {
        let cpu = read_cpuinfo().as_deref().and_then(cpu_model).unwrap_or_else(|| "unknown".to_string());
        let logical_cpus = std::thread::available_parallelism().map_or(1, |n| n.get());
        Host { cpu, logical_cpus, features: simd_features(), build: crate::cpu::build_baseline() }
    }

    /// `host: MODEL, N logical CPUs, features: a b c, build: x86-64-v2` (one line, for the
    /// benchmark's header).
    pub fn line(&self) -> String {
        let features = if self.features.is_empty() { "none".to_string() } else { self.features.join(" ") };
        format!(
            "host: {}, {} logical CPUs, features: {}, build: {}",
            self.cpu, self.logical_cpus, features, self.build
        )
    }

    /// `{"cpu": …, "logical_cpus": …, "features": […], "build": …}`.
    pub fn to_json(&self) -> Value {
        json!({"cpu": self.cpu, "logical_cpus": self.logical_cpus, "features": self.features, "build": self.build})
    }
}

/// The first `model name` of a `/proc/cpuinfo` text, trimmed; `None` when there is none or it
/// is empty.
pub fn cpu_model(cpuinfo: &str) -> Option<String> {
    cpuinfo.lines().find_map(|line| {
        let (key, value) = line.split_once(':')?;
        (key.trim() == "model name").then(|| value.trim().to_string()).filter(|v| !v.is_empty())
    })
}

fn read_cpuinfo() -> Option<String> {
    use std::io::Read;
    let mut text = String::new();
    std::fs::File::open("/proc/cpuinfo").ok()?.take(CPUINFO_CAP).read_to_string(&mut text).ok()?;
    Some(text)
}

fn simd_features() -> Vec<&'static str> {
    #[cfg(target_arch = "x86_64")]
    {
        let mut f = Vec::new();
        if std::arch::is_x86_feature_detected!("avx2") {
            f.push("avx2");
        }
        if std::arch::is_x86_feature_detected!("popcnt") {
            f.push("popcnt");
        }
        if std::arch::is_x86_feature_detected!("fma") {
            f.push("fma");
        }
        if std::arch::is_x86_feature_detected!("avx512f") {
            f.push("avx512f");
        }
        f
    }
    #[cfg(not(target_arch = "x86_64"))]
    Vec::new()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_model_is_the_first_model_name_line() {
        let intel = "processor\t: 0\nvendor_id\t: GenuineIntel\nmodel\t\t: 143\n\
                     model name\t: Intel(R) Xeon(R) Platinum 8481C CPU @ 2.70GHz\nstepping\t: 8\n\n\
                     processor\t: 1\nmodel name\t: something else\n";
        assert_eq!(cpu_model(intel).as_deref(), Some("Intel(R) Xeon(R) Platinum 8481C CPU @ 2.70GHz"));
        let amd = "processor : 0\nmodel name   :   AMD EPYC 9B14  \n";
        assert_eq!(cpu_model(amd).as_deref(), Some("AMD EPYC 9B14"));
        // `model` alone is not the name; an empty name or none at all gives None.
        assert_eq!(cpu_model("model\t: 143\n"), None);
        assert_eq!(cpu_model("model name\t:\n"), None);
        assert_eq!(cpu_model(""), None);
    }

    #[test]
    fn the_line_and_the_json_carry_the_same_fields() {
        let h = Host {
            cpu: "AMD EPYC".into(),
            logical_cpus: 2,
            features: vec!["avx2", "popcnt"],
            build: "x86-64-v2",
        };
        assert_eq!(h.line(), "host: AMD EPYC, 2 logical CPUs, features: avx2 popcnt, build: x86-64-v2");
        assert_eq!(
            h.to_json(),
            json!({"cpu": "AMD EPYC", "logical_cpus": 2, "features": ["avx2", "popcnt"], "build": "x86-64-v2"})
        );
        let bare = Host { cpu: "unknown".into(), logical_cpus: 1, features: vec![], build: "x86-64" };
        assert_eq!(bare.line(), "host: unknown, 1 logical CPUs, features: none, build: x86-64");
        let here = Host::detect();
        assert!(here.logical_cpus >= 1 && !here.cpu.is_empty());
    }
}
