//! The recording's JSON channels: their topics and schemas (the recorder writes them, the
//! Foxglove views derive some from others).

/// The JSON channels.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub enum JsonChannel {
    /// `/imu/sample`.
    ImuSample,
    /// `/nav/event`.
    Event,
    /// `/nav/summary`.
    Summary,
    /// `/nav/attitude` (10 Hz).
    Attitude,
    /// `/gps/fix`.
    Gps,
    /// `/nav/solution` (1 Hz of IMU time while navigating).
    Solution,
    /// `/nav/location` (`foxglove.LocationFix`, derived from `/nav/solution`).
    Location,
    /// `/gps/location` (`foxglove.LocationFix`, derived from `/gps/fix`).
    GpsLocation,
    /// `/nav/pose` (`foxglove.PoseInFrame`, derived from `/nav/solution`).
    Pose,
    /// `/nav/log` (`foxglove.Log`, derived from `/nav/event`).
    Log,
}

impl JsonChannel {
    /// Every JSON channel (each gets its MCAP channel when the file is created).
    pub const ALL: [JsonChannel; 10] = [
        JsonChannel::ImuSample,
        JsonChannel::Event,
        JsonChannel::Summary,
        JsonChannel::Attitude,
        JsonChannel::Gps,
        JsonChannel::Solution,
        JsonChannel::Location,
        JsonChannel::GpsLocation,
        JsonChannel::Pose,
        JsonChannel::Log,
    ];

    /// The channel's JSON schema (`nav/schemas/`): its name and text.
    pub const fn schema(self) -> (&'static str, &'static str) {
        match self {
            JsonChannel::ImuSample => (
                "rlg-hil/nav/imu-sample",
                include_str!("../../schemas/imu-sample.json"),
            ),
            JsonChannel::Event => (
                "rlg-hil/nav/event",
                include_str!("../../schemas/event.json"),
            ),
            JsonChannel::Summary => (
                "rlg-hil/nav/summary",
                include_str!("../../schemas/summary.json"),
            ),
            JsonChannel::Attitude => (
                "rlg-hil/nav/attitude",
                include_str!("../../schemas/attitude.json"),
            ),
            JsonChannel::Gps => (
                "rlg-hil/nav/gps-fix",
                include_str!("../../schemas/gps-fix.json"),
            ),
            JsonChannel::Solution => (
                "rlg-hil/nav/solution",
                include_str!("../../schemas/solution.json"),
            ),
            JsonChannel::Location | JsonChannel::GpsLocation => (
                "foxglove.LocationFix",
                include_str!("../../schemas/foxglove/LocationFix.json"),
            ),
            JsonChannel::Pose => (
                "foxglove.PoseInFrame",
                include_str!("../../schemas/foxglove/PoseInFrame.json"),
            ),
            JsonChannel::Log => (
                "foxglove.Log",
                include_str!("../../schemas/foxglove/Log.json"),
            ),
        }
    }

    /// The channel's MCAP topic.
    pub fn topic(self) -> &'static str {
        match self {
            JsonChannel::ImuSample => "/imu/sample",
            JsonChannel::Event => "/nav/event",
            JsonChannel::Summary => "/nav/summary",
            JsonChannel::Attitude => "/nav/attitude",
            JsonChannel::Gps => "/gps/fix",
            JsonChannel::Solution => "/nav/solution",
            JsonChannel::Location => "/nav/location",
            JsonChannel::GpsLocation => "/gps/location",
            JsonChannel::Pose => "/nav/pose",
            JsonChannel::Log => "/nav/log",
        }
    }
}
