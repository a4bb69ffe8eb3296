//! The algorithms of the paper, as pure code: segmentation of the mouse in the depth image,
//! the forests and their discriminative training, the paw cascade, fusion into 24 joints and
//! the calibration maths; and the behaviour and gait measures read from a run's poses. They know nothing of threads or the command line, and open only the
//! files they are asked to (models, calibrations).

pub mod behaviour;
pub mod body_shape;
pub mod calibrate;
pub mod forest;
pub mod fusion;
pub mod identity;
pub mod measure;
pub mod movement;
pub mod orientation;
pub mod paws;
pub mod segment;
pub mod smoothing;
pub mod tail;
