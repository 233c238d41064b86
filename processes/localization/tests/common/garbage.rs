//! The values the garbage property tests draw from: ordinary numbers, the non-finite ones, signed
//! zeros, the smallest positive float, and finite values far beyond any physical bound.

use proptest::prelude::*;

/// Any f64 a corrupt or hostile message could carry.
pub fn any_f64() -> impl Strategy<Value = f64> {
    prop_oneof![
        -10.0..10.0f64,
        Just(f64::NAN),
        Just(f64::INFINITY),
        Just(f64::NEG_INFINITY),
        Just(0.0),
        Just(-0.0),
        Just(1e300),
        Just(-1e300),
        Just(1e6),
        Just(1e9),
        Just(f64::MIN_POSITIVE),
    ]
}
