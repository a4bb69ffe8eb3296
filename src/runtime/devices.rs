//! `mousepose devices`: the cameras each registered backend can see (`capture::backend`).
//!
//! OpenNI2 and V4L2 list local devices (USB, device nodes). Aravis never broadcasts: GigE
//! Vision cameras are looked for only at the addresses a rig config names (Aravis 0.8 cannot
//! limit its discovery to one network interface, so no discovery is run at all).

use crate::runtime::capture::backend::Backend;
pub use crate::runtime::capture::backend::BackendDevices;
use crate::runtime::capture::{COLOR_BACKENDS, DEPTH_BACKENDS};
use crate::runtime::config::Config;

/// Lists every backend's cameras, each backend as the camera `config` gives it sees it (GigE
/// cameras only at the address it names).
pub fn list(config: Option<&Config>) -> Vec<BackendDevices> {
    // The configured cameras' backends, and their own listings.
    let depth = config.map(|c| (c.depth.backend(), c.depth.devices()));
    let color = config
        .and_then(|c| c.color.as_ref())
        .map(|c| (c.backend(), c.devices()));
    let mut found = listings(DEPTH_BACKENDS, depth);
    found.extend(listings(COLOR_BACKENDS, color));
    found
}

/// Each backend's listing: the configured camera's own when it is of that backend and has one.
fn listings<C: ?Sized>(
    backends: &[Backend<C>],
    mut configured: Option<(&'static str, Option<BackendDevices>)>,
) -> Vec<BackendDevices> {
    backends
        .iter()
        .filter_map(|b| {
            let own = configured
                .as_mut()
                .filter(|(name, _)| *name == b.name)
                .and_then(|(_, d)| d.take());
            own.or_else(|| b.list.map(|list| list()))
        })
        .collect()
}
