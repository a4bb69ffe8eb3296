//! mousepose: live 3D pose of a lab mouse from a depth camera above its cage and a colour
//! camera under its glass floor. See `docs/ARCHITECTURE.md` for how the parts fit.

pub mod frame;
pub mod geometry;
pub mod kinematics;
pub mod pose;
pub mod session;
pub mod skeleton;
pub mod store;
