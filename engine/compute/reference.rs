//! CPU references of the GPU primitives: the GPU results must equal these exactly.

/// Exclusive prefix sum (wrapping modulo 2^32) and the total.
pub fn exclusive_scan(data: &[u32]) -> (Vec<u32>, u32) {
    let mut out = Vec::with_capacity(data.len());
    let mut sum = 0u32;
    for &x in data {
        out.push(sum);
        sum = sum.wrapping_add(x);
    }
    (out, sum)
}

/// Stable stream compaction: the values whose flag is non-zero, in order.
pub fn compact(values: &[u32], flags: &[u32]) -> Vec<u32> {
    values
        .iter()
        .zip(flags)
        .filter(|(_, &f)| f != 0)
        .map(|(&v, _)| v)
        .collect()
}

/// Stable sort of (key, value) pairs by key.
pub fn sort_pairs<K: Ord + Copy>(keys: &[K], values: &[u32]) -> (Vec<K>, Vec<u32>) {
    let mut pairs: Vec<(K, u32)> = keys.iter().copied().zip(values.iter().copied()).collect();
    // `sort_by_key` is stable: equal keys keep their value order.
    pairs.sort_by_key(|p| p.0);
    pairs.into_iter().unzip()
}

/// Workgroups `[x, y, z]` of the indirect arguments the GPU writes for `count` items in groups
/// of `group_size`: `ceil(count / group_size)` as a 2D grid with `x <= 65535`.
pub fn indirect_args(count: u32, group_size: u32) -> [u32; 3] {
    let groups = (count as u64).div_ceil(group_size as u64);
    [
        groups.min(super::GRID_X as u64) as u32,
        groups.div_ceil(super::GRID_X as u64).max(1) as u32,
        1,
    ]
}
