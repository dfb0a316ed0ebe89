//! The front end: the devices' data as nav takes it in, before navigation.

pub mod coning;
pub mod dither_filter;
pub mod gps_receiver;
pub mod imu_clock;
pub mod imu_frames;
pub mod processing;
