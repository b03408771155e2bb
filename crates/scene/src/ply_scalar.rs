//! The scalar types of the PLY format (Turk 1994), shared by every PLY reader in the workspace
//! (meshes and point clouds in `fewview-geom`, Gaussian models in `fewview-splat`).

/// A PLY property type, under its classic (`uchar`, `float`) or sized (`uint8`, `float32`) name.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlyScalar {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl PlyScalar {
    /// The type a header names, if it is one of PLY's eight.
    pub fn parse(s: &str) -> Option<Self> {
        Some(match s {
            "char" | "int8" => Self::I8,
            "uchar" | "uint8" => Self::U8,
            "short" | "int16" => Self::I16,
            "ushort" | "uint16" => Self::U16,
            "int" | "int32" => Self::I32,
            "uint" | "uint32" => Self::U32,
            "float" | "float32" => Self::F32,
            "double" | "float64" => Self::F64,
            _ => return None,
        })
    }

    /// Bytes per value in a binary body.
    pub fn size(self) -> usize {
        match self {
            Self::I8 | Self::U8 => 1,
            Self::I16 | Self::U16 => 2,
            Self::I32 | Self::U32 | Self::F32 => 4,
            Self::F64 => 8,
        }
    }

    /// The value of the first [`size`](Self::size) bytes of `b` in the given byte order. Every
    /// type converts to `f64` exactly (so an `f32` keeps its bits through a round trip).
    ///
    /// Panics if `b` is shorter than the type; readers check the body's length first.
    pub fn decode(self, b: &[u8], little_endian: bool) -> f64 {
        let n = self.size();
        let mut a = [0u8; 8];
        a[..n].copy_from_slice(&b[..n]);
        if !little_endian {
            a[..n].reverse();
        }
        match self {
            Self::I8 => a[0] as i8 as f64,
            Self::U8 => a[0] as f64,
            Self::I16 => i16::from_le_bytes([a[0], a[1]]) as f64,
            Self::U16 => u16::from_le_bytes([a[0], a[1]]) as f64,
            Self::I32 => i32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
            Self::U32 => u32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
            Self::F32 => f32::from_le_bytes([a[0], a[1], a[2], a[3]]) as f64,
            Self::F64 => f64::from_le_bytes(a),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn decodes_both_byte_orders() {
        let x = -1234.5678f32;
        let le = x.to_le_bytes();
        let be = x.to_be_bytes();
        assert_eq!(PlyScalar::F32.decode(&le, true), x as f64);
        assert_eq!(PlyScalar::F32.decode(&be, false), x as f64);
        assert_eq!(
            PlyScalar::I16.decode(&(-300i16).to_be_bytes(), false),
            -300.0
        );
        assert_eq!(
            PlyScalar::U32.decode(&70000u32.to_le_bytes(), true),
            70000.0
        );
        assert_eq!(PlyScalar::I8.decode(&[0xff], true), -1.0);
        assert_eq!(PlyScalar::parse("uint8"), Some(PlyScalar::U8));
        assert_eq!(PlyScalar::parse("half"), None);
    }
}
