//! Navigation: the earth model, strapdown navigation, the SINS/GPS filter and its integrity,
//! the navigation mode and the solution it sends.

pub mod earth;
pub mod filter;
pub mod integrity;
pub mod navigator;
pub mod solution_frames;
pub mod strapdown;
