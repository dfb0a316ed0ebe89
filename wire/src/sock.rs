//! Conversion between [`RawFrame`] and `socketcan::CanFrame`.

use crate::RawFrame;
use socketcan::{CanFrame, EmbeddedFrame, Id, StandardId};
use thiserror::Error;

/// A socketcan frame that is not a classic standard-id data frame.
#[derive(Debug, Error, Clone, PartialEq, Eq)]
pub enum FrameConvError {
    /// Extended identifier.
    #[error("extended-id frame 0x{0:08X}: the contract uses 11-bit ids only")]
    Extended(u32),
    /// Remote request.
    #[error("remote frame 0x{0:03X}: the contract has no remote frames")]
    Remote(u32),
    /// Error frame from the controller.
    #[error("CAN error frame (class 0x{0:08X})")]
    Error(u32),
    /// Id out of range for a standard frame.
    #[error("id 0x{0:X} does not fit an 11-bit identifier")]
    BadId(u16),
}

/// Convert a received socketcan frame.
pub fn from_can_frame(f: &CanFrame) -> Result<RawFrame, FrameConvError> {
    match f {
        CanFrame::Data(d) => match d.id() {
            Id::Standard(id) => {
                let mut data = [0u8; 8];
                let p = d.data();
                data[..p.len()].copy_from_slice(p);
                Ok(RawFrame {
                    id: id.as_raw(),
                    len: p.len() as u8,
                    data,
                })
            }
            Id::Extended(id) => Err(FrameConvError::Extended(id.as_raw())),
        },
        CanFrame::Remote(r) => Err(FrameConvError::Remote(match r.id() {
            Id::Standard(id) => u32::from(id.as_raw()),
            Id::Extended(id) => id.as_raw(),
        })),
        CanFrame::Error(e) => Err(FrameConvError::Error(e.error_bits())),
    }
}

/// Convert a frame for sending.
pub fn to_can_frame(f: &RawFrame) -> Result<CanFrame, FrameConvError> {
    let id = StandardId::new(f.id).ok_or(FrameConvError::BadId(f.id))?;
    CanFrame::new(id, f.payload()).ok_or(FrameConvError::BadId(f.id))
}
