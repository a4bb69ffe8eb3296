//! Reproducible experiments from the paper.

pub mod gauss2d;
