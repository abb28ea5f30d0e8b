//! The one GPU device the GPU methods of a run share.

use std::sync::{Arc, OnceLock};

use shadow_core::{Error, Result, gpu::GpuContext};

/// The GPU context every GPU method of a run shares, opened when the first
/// one is built (so that a run of CPU methods needs no adapter).
#[derive(Debug, Default)]
pub struct SharedGpu {
    context: OnceLock<std::result::Result<Arc<GpuContext>, String>>,
}

impl SharedGpu {
    /// A device opened on first use ([`GpuContext::new`]).
    pub fn new() -> SharedGpu {
        SharedGpu::default()
    }

    /// `context` for every GPU method (a test's, or a host's device).
    pub fn with(context: Arc<GpuContext>) -> SharedGpu {
        let shared = SharedGpu::default();
        let _ = shared.context.set(Ok(context));
        shared
    }

    /// The shared context, opening it on first use; a failure to open is
    /// the same error for every later call.
    pub fn get(&self) -> Result<Arc<GpuContext>> {
        let opened = self.context.get_or_init(|| {
            GpuContext::new().map(Arc::new).map_err(|e| match e {
                Error::Gpu(message) => message,
                other => other.to_string(),
            })
        });
        opened.clone().map_err(Error::Gpu)
    }

    /// The adapter the shared device runs on, once a method opened it.
    pub fn adapter(&self) -> Option<String> {
        match self.context.get()? {
            Ok(context) => Some(context.adapter.to_string()),
            Err(_) => None,
        }
    }
}
