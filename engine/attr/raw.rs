//! The raw colour format: one RGBA8 word per colour (HashDAG's edit-time storage). Decoding
//! forces alpha to 255, like every other format.

use super::AttrError;

/// Stored words of `colors`: the colours themselves, alpha forced to 255.
pub fn encode(colors: &[u32]) -> Vec<u32> {
    colors.iter().map(|&c| c | 0xff00_0000).collect()
}

/// Every colour of a chunk of `count` colours.
pub fn decode_all(words: &[u32], count: usize) -> Result<Vec<u32>, AttrError> {
    check_len(words, count)?;
    Ok(words.iter().map(|&c| c | 0xff00_0000).collect())
}

/// Colour `index` of a chunk of `count` colours.
pub fn decode(words: &[u32], count: usize, index: usize) -> Result<u32, AttrError> {
    check_len(words, count)?;
    if index >= count {
        return Err(AttrError::IndexOutOfRange {
            index: index as u64,
            count: count as u64,
        });
    }
    Ok(words[index] | 0xff00_0000)
}

/// A raw chunk holds exactly one word per colour.
fn check_len(words: &[u32], count: usize) -> Result<(), AttrError> {
    if words.len() != count {
        return Err(AttrError::Corrupt {
            format: "raw",
            word: words.len().min(count) as u64,
            reason: format!("{} words for {count} colours", words.len()),
        });
    }
    Ok(())
}
