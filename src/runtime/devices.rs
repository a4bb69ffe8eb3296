//! `mousepose devices`: the cameras each backend can see.
//!
//! OpenNI2 and V4L2 list local devices (USB, device nodes). Aravis never broadcasts: GigE
//! Vision cameras are looked for only at the addresses a rig config names (Aravis 0.8 cannot
//! limit its discovery to one network interface, so no discovery is run at all).

use crate::runtime::capture::{DeviceInfo, error_chain};
use crate::runtime::config::{ColorCamera, Config};
use serde::Serialize;

/// What one backend reported.
#[derive(Debug, Serialize)]
pub struct BackendDevices {
    pub backend: &'static str,
    pub devices: Vec<DeviceInfo>,
    /// Why the backend could not list its devices, if it could not.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// What the listing covers (e.g. which addresses were probed).
    pub scope: String,
}

/// Lists every backend's cameras; GigE cameras only at the addresses `config` names.
pub fn list(config: Option<&Config>) -> Vec<BackendDevices> {
    let openni = crate::runtime::capture::openni::list_devices();
    let addresses: Vec<String> = config
        .and_then(|c| c.color.as_ref())
        .and_then(|c| match c {
            ColorCamera::Aravis { address, .. } => address.clone(),
            ColorCamera::V4l2 { .. } => None,
        })
        .into_iter()
        .collect();
    let aravis = crate::runtime::capture::aravis::list_devices(&addresses);
    vec![
        BackendDevices {
            backend: "openni2",
            error: openni.as_ref().err().map(|e| error_chain(e)),
            devices: openni.unwrap_or_default(),
            scope: "USB depth cameras and the drivers' virtual devices".to_owned(),
        },
        BackendDevices {
            backend: "aravis",
            devices: aravis,
            error: None,
            scope: if addresses.is_empty() {
                "no GigE Vision address configured (no broadcast discovery is ever sent; name the \
                 camera's address in the rig config's [color] table and pass --config)"
                    .to_owned()
            } else {
                format!("GigE Vision cameras at {}", addresses.join(", "))
            },
        },
        BackendDevices {
            backend: "v4l2",
            devices: crate::runtime::capture::v4l2::list_devices(),
            error: None,
            scope: "video capture nodes under /dev".to_owned(),
        },
    ]
}
