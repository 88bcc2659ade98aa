//! The slab pool seen from the host: super blocks (one buffer each: 16 block bitmasks, then
//! 16 384 zeroed slabs), the super-block address table the shaders index, and the status block.
//!
//! The GPU side is `shaders/glsl/hash/alloc.glsl` (`hash_alloc_slab`, `hash_free_slab`). The host
//! only adds super blocks between passes and reads occupancy; it never allocates single slabs.

use std::sync::Arc;

use super::layout::{
    HashStatus, SlabLayout, BLOCKS_PER_SUPER_BLOCK, MAX_SUPER_BLOCKS, SLABS_PER_SUPER_BLOCK,
    STATUS_WORDS, SUPER_BLOCK_BITMASK_WORDS,
};
use super::HashError;
use crate::gpu::{Buffer, GpuContext, MemLocation};

/// Occupancy of the pool, counted from the block bitmasks.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PoolOccupancy {
    /// Super blocks in the pool.
    pub super_blocks: u32,
    /// Slabs the pool can hold (super blocks x 16 384).
    pub capacity_slabs: u64,
    /// Slabs whose bitmask bit is set.
    pub allocated_slabs: u64,
    /// Allocated slabs per memory block (super block-major, 16 per super block).
    pub per_block: Vec<u32>,
}

/// The GPU slab pool of one table.
pub struct SlabPool {
    ctx: Arc<GpuContext>,
    layout: SlabLayout,
    super_blocks: Vec<Buffer>,
    table: Buffer,
    status: Buffer,
}

impl SlabPool {
    /// An empty pool with `super_blocks` zeroed super blocks (at least one).
    pub fn new(
        ctx: &Arc<GpuContext>,
        layout: SlabLayout,
        super_blocks: u32,
    ) -> Result<SlabPool, HashError> {
        let table = ctx.create_buffer(
            "hash super-block table",
            8 * MAX_SUPER_BLOCKS as u64,
            MemLocation::GpuOnly,
        )?;
        let status =
            ctx.create_buffer("hash status", 4 * STATUS_WORDS as u64, MemLocation::GpuOnly)?;
        let mut cmd = ctx.begin_commands("hash pool init")?;
        cmd.fill_buffer(&table, 0);
        cmd.fill_buffer(&status, 0);
        // No wait: later submissions on the queue are ordered after it.
        cmd.submit_async()?;
        let mut pool = SlabPool {
            ctx: Arc::clone(ctx),
            layout,
            super_blocks: Vec::new(),
            table,
            status,
        };
        pool.grow(super_blocks.max(1))?;
        Ok(pool)
    }

    /// Adds `count` zeroed super blocks (between passes only).
    pub fn grow(&mut self, count: u32) -> Result<(), HashError> {
        let have = self.super_blocks.len() as u32;
        if have + count > MAX_SUPER_BLOCKS {
            return Err(HashError::Exhausted {
                items: 0,
                super_blocks: have,
            });
        }
        let bytes = self.layout.super_block_bytes();
        let mut addresses = Vec::with_capacity(count as usize);
        let mut added = Vec::with_capacity(count as usize);
        for i in have..have + count {
            let buf = self.ctx.create_buffer(
                &format!("hash super block {i}"),
                bytes,
                MemLocation::GpuOnly,
            )?;
            addresses.push(buf.address());
            added.push(buf);
        }
        {
            // Zero the new super blocks and append their addresses to the table in one
            // submission, not waited for: later passes on the queue are ordered after it.
            let mut cmd = self.ctx.begin_commands("hash pool grow")?;
            for buf in &added {
                cmd.fill_buffer(buf, 0);
            }
            cmd.upload(&self.table, 8 * have as u64, &addresses)?;
            cmd.submit_async()?;
        }
        self.super_blocks.extend(added);
        Ok(())
    }

    /// The slab layout.
    pub fn layout(&self) -> SlabLayout {
        self.layout
    }

    /// Super blocks in the pool.
    pub fn super_block_count(&self) -> u32 {
        self.super_blocks.len() as u32
    }

    /// Memory blocks in the pool (super blocks x 16); the shaders' `push.blocks`.
    pub fn block_count(&self) -> u32 {
        self.super_block_count() * BLOCKS_PER_SUPER_BLOCK
    }

    /// Slabs the pool can hold.
    pub fn capacity_slabs(&self) -> u64 {
        self.super_block_count() as u64 * SLABS_PER_SUPER_BLOCK as u64
    }

    /// Device address of the super-block address table (`push.super_blocks`).
    pub fn table_address(&self) -> u64 {
        self.table.address()
    }

    /// Device address of the status block (`push.status`).
    pub fn status_address(&self) -> u64 {
        self.status.address()
    }

    /// The super block buffers, in pool order.
    pub fn super_blocks(&self) -> &[Buffer] {
        &self.super_blocks
    }

    /// Device memory of the pool (super blocks, address table, status), in bytes.
    pub fn gpu_bytes(&self) -> u64 {
        self.super_blocks.iter().map(Buffer::size).sum::<u64>()
            + self.table.size()
            + self.status.size()
    }

    /// The status block buffer (one [`HashStatus`]).
    pub fn status_buffer(&self) -> &Buffer {
        &self.status
    }

    /// Reads the status block back (one small readback through the readback ring).
    pub fn read_status(&self) -> Result<HashStatus, HashError> {
        let words: Vec<HashStatus> = self.ctx.download(&self.status)?;
        Ok(words[0])
    }

    /// Reads every block bitmask back and counts allocated slabs.
    pub fn occupancy(&self) -> Result<PoolOccupancy, HashError> {
        let mut per_block = Vec::with_capacity(self.block_count() as usize);
        for buf in &self.super_blocks {
            let masks: Vec<u32> =
                self.ctx
                    .read_buffer(buf, 0, SUPER_BLOCK_BITMASK_WORDS as usize)?;
            per_block.extend(
                masks
                    .chunks(SUPER_BLOCK_BITMASK_WORDS as usize / BLOCKS_PER_SUPER_BLOCK as usize)
                    .map(|block| block.iter().map(|m| m.count_ones()).sum::<u32>()),
            );
        }
        Ok(PoolOccupancy {
            super_blocks: self.super_block_count(),
            capacity_slabs: self.capacity_slabs(),
            allocated_slabs: per_block.iter().map(|&n| n as u64).sum(),
            per_block,
        })
    }

    /// Downloads every super block (bitmasks and slabs) as words, in pool order.
    pub fn download_super_blocks(&self) -> Result<Vec<Vec<u32>>, HashError> {
        self.super_blocks
            .iter()
            .map(|b| self.ctx.download::<u32>(b).map_err(HashError::from))
            .collect()
    }
}
