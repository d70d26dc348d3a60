//! Which renderer draws: the GPU, the CPU (the reference), or the GPU when there is one.

use anyhow::{Context, Result};

use super::context::Gpu;

/// `--backend gpu|cpu|auto`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Backend {
    /// The GPU when a hardware adapter exists, else the CPU (a software adapter such as
    /// lavapipe only with `gpu`: it draws 10–40× slower than the CPU path, docs/gpu.md).
    #[default]
    Auto,
    /// The GPU; an error without an adapter.
    Gpu,
    /// The CPU reference.
    Cpu,
}

impl std::str::FromStr for Backend {
    type Err = anyhow::Error;
    fn from_str(s: &str) -> Result<Backend> {
        match s {
            "auto" => Ok(Backend::Auto),
            "gpu" => Ok(Backend::Gpu),
            "cpu" => Ok(Backend::Cpu),
            _ => anyhow::bail!("unknown backend {s:?} (gpu, cpu or auto)"),
        }
    }
}

impl Backend {
    /// The GPU this backend draws with (`None`: the CPU), and a line saying what was chosen.
    pub fn resolve(self) -> Result<(Option<&'static Gpu>, String)> {
        match self {
            Backend::Cpu => Ok((None, "backend: CPU".into())),
            Backend::Gpu => {
                let gpu = Gpu::shared().context("--backend gpu")?;
                Ok((Some(gpu), format!("backend: GPU, {}", gpu.adapter)))
            }
            Backend::Auto => match Gpu::shared() {
                Ok(gpu) if gpu.software => Ok((
                    None,
                    format!(
                        "backend: CPU (the only adapter, {}, is a software rasteriser; \
                         --backend gpu uses it)",
                        gpu.adapter
                    ),
                )),
                Ok(gpu) => Ok((Some(gpu), format!("backend: GPU, {}", gpu.adapter))),
                Err(e) => Ok((None, format!("backend: CPU (no GPU: {e:#})"))),
            },
        }
    }
}
