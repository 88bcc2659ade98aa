//! Length-limited canonical Huffman codes (package-merge), emitted least-significant bit first
//! so a decoder can read a pointer word from its low bits.

/// Longest code the encoder emits and the decoder accepts.
pub const MAX_CODE_LEN: u8 = 15;

/// Optimal code lengths under a length limit (package-merge, Larmore & Hirschberg 1990).
///
/// Symbols of weight 0 get length 0 (no code). A single used symbol gets length 0 too: it is
/// implied and costs no bit. Returns `None` when `2^limit` is smaller than the number of used
/// symbols.
pub fn length_limited_code_lengths(weights: &[u64], limit: u8) -> Option<Vec<u8>> {
    let used: Vec<usize> = (0..weights.len()).filter(|&s| weights[s] > 0).collect();
    let mut lengths = vec![0u8; weights.len()];
    if used.len() <= 1 {
        return Some(lengths);
    }
    if limit >= 64 || (1u64 << limit) < used.len() as u64 {
        return None;
    }
    let mut leaves: Vec<(u64, Vec<u16>)> =
        used.iter().map(|&s| (weights[s], vec![s as u16])).collect();
    leaves.sort_by(|a, b| a.0.cmp(&b.0).then(a.1.cmp(&b.1)));
    let mut list = leaves.clone();
    for _ in 1..limit {
        let mut packages: Vec<(u64, Vec<u16>)> = list
            .chunks_exact(2)
            .map(|p| {
                let mut syms = p[0].1.clone();
                syms.extend_from_slice(&p[1].1);
                (p[0].0.saturating_add(p[1].0), syms)
            })
            .collect();
        // Merge (stable: leaves before packages of equal weight).
        let mut merged = Vec::with_capacity(leaves.len() + packages.len());
        let (mut i, mut j) = (0, 0);
        while i < leaves.len() || j < packages.len() {
            if j >= packages.len() || (i < leaves.len() && leaves[i].0 <= packages[j].0) {
                merged.push(leaves[i].clone());
                i += 1;
            } else {
                merged.push(std::mem::take(&mut packages[j]));
                j += 1;
            }
        }
        list = merged;
    }
    for item in list.iter().take(2 * used.len() - 2) {
        for &s in &item.1 {
            lengths[s as usize] += 1;
        }
    }
    Some(lengths)
}

/// A canonical prefix code over `lengths.len()` symbols (length 0 = unused, unless it is the only
/// symbol, which then takes no bits).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Huffman {
    /// Code length per symbol.
    pub lengths: Vec<u8>,
    /// Emitted code per symbol (bit-reversed canonical code: first bit in bit 0).
    codes: Vec<u32>,
    /// Symbols sorted by (length, symbol).
    sorted: Vec<u16>,
    /// Per length: number of codes.
    count: [u32; MAX_CODE_LEN as usize + 1],
    /// The only used symbol when exactly one has length 0 and none has a code.
    single: Option<u16>,
}

impl Huffman {
    /// Builds the canonical code of given lengths; `None` unless the lengths form a prefix code
    /// (Kraft sum at most 1, lengths at most `MAX_CODE_LEN`) or name exactly one implied symbol.
    pub fn from_lengths(lengths: Vec<u8>, single: Option<u16>) -> Option<Huffman> {
        if lengths.len() > u16::MAX as usize {
            return None;
        }
        let mut count = [0u32; MAX_CODE_LEN as usize + 1];
        for &l in &lengths {
            if l > MAX_CODE_LEN {
                return None;
            }
            if l > 0 {
                count[l as usize] += 1;
            }
        }
        let coded: u32 = count.iter().sum();
        if let Some(s) = single {
            if coded != 0 || s as usize >= lengths.len() {
                return None;
            }
        } else if coded == 0 {
            return None;
        }
        // Kraft inequality.
        let kraft: u64 = (1..=MAX_CODE_LEN as usize)
            .map(|l| (count[l] as u64) << (MAX_CODE_LEN as usize - l))
            .sum();
        if kraft > 1 << MAX_CODE_LEN {
            return None;
        }
        let mut sorted: Vec<u16> = (0..lengths.len() as u16)
            .filter(|&s| lengths[s as usize] > 0)
            .collect();
        sorted.sort_by_key(|&s| (lengths[s as usize], s));
        let mut codes = vec![0u32; lengths.len()];
        let mut code = 0u32;
        let mut prev_len = 0u8;
        for &s in &sorted {
            let l = lengths[s as usize];
            code <<= l - prev_len;
            prev_len = l;
            codes[s as usize] = code.reverse_bits() >> (32 - l as u32);
            code += 1;
        }
        Some(Huffman {
            lengths,
            codes,
            sorted,
            count,
            single,
        })
    }

    /// The optimal length-limited code for symbol weights (`None` if no symbol is used).
    pub fn from_weights(weights: &[u64]) -> Option<Huffman> {
        let lengths = length_limited_code_lengths(weights, MAX_CODE_LEN)?;
        let used: Vec<usize> = (0..weights.len()).filter(|&s| weights[s] > 0).collect();
        let single = (used.len() == 1).then(|| used[0] as u16);
        if used.is_empty() {
            return None;
        }
        Huffman::from_lengths(lengths, single)
    }

    /// The implied symbol of a one-symbol code.
    pub fn single(&self) -> Option<u16> {
        self.single
    }

    /// `(code, length)` of a symbol (first bit in bit 0); `None` when it has no code.
    pub fn encode(&self, symbol: usize) -> Option<(u32, u8)> {
        if self.single == Some(symbol as u16) {
            return Some((0, 0));
        }
        let l = *self.lengths.get(symbol)?;
        (l > 0).then(|| (self.codes[symbol], l))
    }

    /// Decodes the symbol in the low bits of `bits`: `(symbol, length)`; `None` for bits that
    /// start no code.
    pub fn decode(&self, bits: u64) -> Option<(u16, u8)> {
        if let Some(s) = self.single {
            return Some((s, 0));
        }
        let mut code = 0u32; // canonical code read so far
        let mut first = 0u32; // first canonical code of the current length
        let mut index = 0u32; // index in `sorted` of that first code
        for l in 1..=MAX_CODE_LEN as usize {
            code |= ((bits >> (l - 1)) & 1) as u32;
            let n = self.count[l];
            if code < first + n {
                return Some((self.sorted[(index + code - first) as usize], l as u8));
            }
            index += n;
            first = (first + n) << 1;
            code <<= 1;
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn limited_lengths_are_prefix_codes_and_round_trip() {
        // Fibonacci weights force long codes without a limit.
        let mut w = vec![1u64, 1];
        while w.len() < 30 {
            let n = w[w.len() - 1] + w[w.len() - 2];
            w.push(n);
        }
        for limit in [5u8, 8, 15] {
            let lengths = length_limited_code_lengths(&w, limit).unwrap();
            assert!(lengths.iter().all(|&l| l >= 1 && l <= limit));
            let h = Huffman::from_lengths(lengths, None).unwrap();
            for s in 0..w.len() {
                let (code, len) = h.encode(s).unwrap();
                let extra = 0b1011u64 << len;
                assert_eq!(h.decode(code as u64 | extra), Some((s as u16, len)));
            }
        }
        // Unlimited optimum for 4 equal weights is 2 bits each.
        assert_eq!(
            length_limited_code_lengths(&[3, 3, 3, 3], 16).unwrap(),
            vec![2, 2, 2, 2]
        );
        assert_eq!(
            length_limited_code_lengths(&[0, 5, 0], 16).unwrap(),
            vec![0, 0, 0]
        );
        assert!(length_limited_code_lengths(&[1, 1, 1, 1, 1], 2).is_none());
    }
}
