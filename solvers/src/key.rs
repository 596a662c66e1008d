//! Symbolic keys that name variables, in the style of GTSAM's `Symbol`.
//!
//! A [`Key`] packs a one-byte character and a 56-bit index: `X(3)` is pose 3,
//! `V(3)` its velocity, `B(3)` its IMU biases, `L(17)` landmark 17.

use std::fmt;

/// Name of one variable: a character tag and an index.
#[derive(Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Key(u64);

const INDEX_BITS: u32 = 56;
const INDEX_MASK: u64 = (1 << INDEX_BITS) - 1;

impl Key {
    /// Key with character `c` (ASCII) and index `i` (< 2^56).
    pub const fn new(c: char, i: u64) -> Key {
        Key(((c as u64 & 0xff) << INDEX_BITS) | (i & INDEX_MASK))
    }
    /// The character tag.
    pub fn chr(self) -> char {
        ((self.0 >> INDEX_BITS) as u8) as char
    }
    /// The index.
    pub fn index(self) -> u64 {
        self.0 & INDEX_MASK
    }
    /// The packed 64-bit value (tag in the top byte).
    pub fn raw(self) -> u64 {
        self.0
    }
}

impl fmt::Debug for Key {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}({})", self.chr(), self.index())
    }
}
impl fmt::Display for Key {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Debug::fmt(self, f)
    }
}

macro_rules! symbol_fns {
    ($($name:ident => $c:literal, $doc:literal;)*) => {
        $(
            #[doc = $doc]
            #[allow(non_snake_case)]
            pub const fn $name(i: u64) -> Key { Key::new($c, i) }
        )*
    };
}

symbol_fns! {
    X => 'x', "Key of pose `i` (SE(3) or SE(2)).";
    V => 'v', "Key of velocity `i` [m/s, world frame].";
    B => 'b', "Key of IMU bias `i` (accelerometer then gyroscope).";
    L => 'l', "Key of landmark `i`.";
    C => 'c', "Key of camera `i` (bundle adjustment).";
    P => 'p', "Key of a generic parameter block `i`.";
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn roundtrip() {
        let k = X(12345);
        assert_eq!(k.chr(), 'x');
        assert_eq!(k.index(), 12345);
        assert_eq!(format!("{k}"), "x(12345)");
        assert_ne!(X(1), L(1));
        assert!(X(1) < X(2));
    }
}
