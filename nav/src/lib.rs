//! Navigation library of the RLG strapdown INS: earth model, IMU front end, configuration,
//! recording. The `nav` binary is the production program; it opens the devices named in its
//! config file and knows nothing of emulators.

pub mod arrival;
pub mod attitude;
pub mod calib;
pub mod channels;
pub mod cli;
pub mod config;
pub mod coning;
pub mod earth;
pub mod fir;
pub mod foxglove;
pub mod gps;
pub mod gpsport;
pub mod imu;
pub mod imuclock;
pub mod integrity;
pub mod kf;
mod mission;
pub mod navigator;
pub mod northfind;
pub mod northplan;
pub mod output;
pub mod params;
pub mod pipeline;
pub mod procedure;
pub mod rawmsg;
pub mod record;
pub mod redundant;
pub mod selfcal;
pub mod strapdown;
pub mod summary;
pub mod tetracal;
pub mod ttlink;
