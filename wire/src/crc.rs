//! The checksums vehicle networks protect their frames with: a CRC of 8 or 16 bits over named
//! bytes, given by its polynomial, start value, final XOR and bit order (the parameters of the
//! CRC catalogue's entries), so that a lab's layout names its own. Each of the named ones is
//! tested against the catalogue's check value (the CRC of the ASCII bytes `123456789`).

/// A CRC of up to 16 bits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Crc {
    /// Width, bits (1 to 16).
    pub width: u8,
    /// The polynomial, without its top bit (normal form: 0x1D for x^8+x^4+x^3+x^2+1).
    pub poly: u16,
    /// The register's start value.
    pub init: u16,
    /// Each byte taken least significant bit first.
    pub reflect_in: bool,
    /// The result's bits reversed before the final XOR.
    pub reflect_out: bool,
    /// XORed into the result.
    pub xor_out: u16,
}

impl Crc {
    /// CRC-8/SAE-J1850 (poly 0x1D, init 0xFF, xor 0xFF): vehicle networks' end-to-end CRC.
    pub const SAE_J1850: Self = Self::normal(8, 0x1D, 0xFF, 0xFF);
    /// CRC-8/AUTOSAR (poly 0x2F, init 0xFF, xor 0xFF): AUTOSAR E2E profile 2's.
    pub const AUTOSAR_8: Self = Self::normal(8, 0x2F, 0xFF, 0xFF);
    /// CRC-8/SMBUS (poly 0x07, init 0, xor 0).
    pub const SMBUS: Self = Self::normal(8, 0x07, 0x00, 0x00);
    /// CRC-16/IBM-3740, also called CCITT-FALSE (poly 0x1021, init 0xFFFF).
    pub const CCITT_FALSE: Self = Self::normal(16, 0x1021, 0xFFFF, 0x0000);
    /// CRC-16/ARC (poly 0x8005, reflected).
    pub const ARC: Self = Self {
        width: 16,
        poly: 0x8005,
        init: 0,
        reflect_in: true,
        reflect_out: true,
        xor_out: 0,
    };

    /// A CRC without reflection.
    pub const fn normal(width: u8, poly: u16, init: u16, xor_out: u16) -> Self {
        Self {
            width,
            poly,
            init,
            reflect_in: false,
            reflect_out: false,
            xor_out,
        }
    }

    /// The named CRCs, by the names a mapping file gives them.
    pub fn named(name: &str) -> Option<Self> {
        Some(
            match name.to_ascii_uppercase().replace(['_', ' '], "-").as_str() {
                "CRC-8/SAE-J1850" | "SAE-J1850" => Self::SAE_J1850,
                "CRC-8/AUTOSAR" | "AUTOSAR-8" => Self::AUTOSAR_8,
                "CRC-8/SMBUS" | "CRC-8" => Self::SMBUS,
                "CRC-16/IBM-3740" | "CRC-16/CCITT-FALSE" | "CCITT-FALSE" => Self::CCITT_FALSE,
                "CRC-16/ARC" | "ARC" => Self::ARC,
                _ => return None,
            },
        )
    }

    /// The CRC of `bytes`.
    pub fn compute(&self, bytes: &[u8]) -> u16 {
        let w = u32::from(self.width.clamp(1, 16));
        let top = 1u32 << (w - 1);
        let mask = if w == 16 { 0xFFFF } else { (1u32 << w) - 1 };
        let mut reg = u32::from(self.init) & mask;
        for &b in bytes {
            let b = if self.reflect_in { b.reverse_bits() } else { b };
            for i in (0..8).rev() {
                let bit = u32::from(b >> i & 1);
                let fb = u32::from(reg & top != 0) ^ bit;
                reg = (reg << 1) & mask;
                if fb == 1 {
                    reg ^= u32::from(self.poly) & mask;
                }
            }
        }
        if self.reflect_out {
            reg = (reg.reverse_bits() >> (32 - w)) & mask;
        }
        ((reg ^ u32::from(self.xor_out)) & mask) as u16
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The CRC catalogue's check values: the CRC of the ASCII bytes "123456789".
    #[test]
    fn each_named_crc_gives_its_catalogue_check_value() {
        let check = b"123456789";
        for (name, want) in [
            ("CRC-8/SAE-J1850", 0x4B),
            ("CRC-8/AUTOSAR", 0xDF),
            ("CRC-8/SMBUS", 0xF4),
            ("CRC-16/IBM-3740", 0x29B1),
            ("CRC-16/ARC", 0xBB3D),
        ] {
            let c = Crc::named(name).unwrap_or_else(|| panic!("{name}"));
            assert_eq!(c.compute(check), want, "{name}");
        }
        assert_eq!(Crc::named("crc_16/ccitt_false"), Some(Crc::CCITT_FALSE));
        assert_eq!(Crc::named("CRC-32"), None);
        // a byte changed is caught
        assert_ne!(Crc::SAE_J1850.compute(b"123456788"), 0x4B);
    }
}
