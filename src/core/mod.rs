//! Plain types every layer shares: frames and their stamps, the skeleton and poses, cameras and
//! the rig, the limbs' kinematics, RGB pictures. Nothing here reads a file, a clock or a thread.

pub mod frame;
pub mod geometry;
pub mod image;
pub mod kinematics;
pub mod noise;
pub mod pose;
pub mod rng;
pub mod skeleton;
