//! Counter-based random numbers keyed by (seed, particle, component).
//!
//! A value depends only on its key, never on the order in which values are drawn, so the
//! initial state is the same at any thread count (the hoomd-blue approach).

/// SplitMix64 finaliser: a bijective 64-bit mix with good avalanche.
#[inline]
fn mix(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// A uniform number in (0, 1) for the key (seed, index, stream).
pub fn uniform(seed: u64, index: u64, stream: u64) -> f64 {
    let h = mix(mix(mix(seed ^ 0x9e37_79b9_7f4a_7c15).wrapping_add(index)).wrapping_add(stream));
    // 53 random bits, shifted off zero.
    ((h >> 11) as f64 + 0.5) * (1.0 / (1u64 << 53) as f64)
}

/// A standard normal number for the key (seed, index, component) by Box-Muller.
pub fn normal(seed: u64, index: u64, component: u64) -> f64 {
    let u1 = uniform(seed, index, 2 * component);
    let u2 = uniform(seed, index, 2 * component + 1);
    (-2.0 * u1.ln()).sqrt() * (2.0 * std::f64::consts::PI * u2).cos()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn normal_has_unit_moments() {
        let n = 200_000u64;
        let (mut s, mut s2) = (0.0, 0.0);
        for i in 0..n {
            let x = normal(7, i, 1);
            s += x;
            s2 += x * x;
        }
        let mean = s / n as f64;
        let var = s2 / n as f64 - mean * mean;
        assert!(mean.abs() < 0.01, "mean {mean}");
        assert!((var - 1.0).abs() < 0.01, "var {var}");
    }

    #[test]
    fn keys_are_independent() {
        assert_ne!(uniform(1, 2, 3), uniform(1, 3, 2));
        assert_ne!(uniform(1, 2, 3), uniform(2, 2, 3));
        assert_eq!(uniform(1, 2, 3), uniform(1, 2, 3));
    }
}
