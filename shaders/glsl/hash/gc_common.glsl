// Shared by the garbage-collection passes gc_mark.comp and gc_sweep.comp (dissertation §4.4.3),
// driven by engine/hash/gc.rs. They reuse the tables' push constants and specialization
// constants (hash/common.glsl), with `push.items` naming the GC counters and `push.handles` the
// live handles. TEAM (spec constant 4) lanes work on one bucket: the whole subgroup (workgroups
// of one subgroup, see engine/hash/gc.rs) or a single lane (no subgroup operations at all).
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_arithmetic : require
#extension GL_KHR_shader_subgroup_ballot : require
#extension GL_KHR_shader_subgroup_vote : require

#include "shared/hash_layout.h"
#include "hash/common.glsl"
#include "hash/alloc.glsl"
#include "hash/slab.glsl"

// GC counters at `push.items`; members: `GcCounters` in engine/hash/gpu_shared.rs.
layout(buffer_reference, std430, buffer_reference_align = 4) coherent buffer GcCountersRef {
    GC_COUNTERS_MEMBERS
};
