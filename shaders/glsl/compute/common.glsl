// GPU primitives (engine/compute): buffer types, the 2D workgroup grid and a workgroup-wide
// exclusive sum that works for ANY subgroup size (lavapipe: 4, 8 or 16; NVIDIA 32; AMD 32/64).
// Specialization constants: 0 = workgroup size, 1 = items per invocation.
#extension GL_EXT_buffer_reference : require
#extension GL_EXT_shader_explicit_arithmetic_types_int64 : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_arithmetic : require

layout(local_size_x_id = 0) in;
layout(constant_id = 1) const uint ITEMS = 8;

// Elements a workgroup handles: one "block" (scan) or "tile" (radix sort).
const uint BLOCK = gl_WorkGroupSize.x * ITEMS;

layout(buffer_reference, std430, buffer_reference_align = 4) buffer U32s {
    uint v[];
};
layout(buffer_reference, std430, buffer_reference_align = 8) buffer U64s {
    uint64_t v[];
};

// Grids are 2D (x <= 65535, the smallest maxComputeWorkGroupCount[0] Vulkan allows) so that
// more than 65535 workgroups can run; this is the workgroup's linear index.
uint workgroup_linear() {
    return gl_WorkGroupID.x + gl_WorkGroupID.y * gl_NumWorkGroups.x;
}

// One entry per subgroup (at most one per invocation, whatever the subgroup size).
shared uint wg_subgroup_sums[gl_WorkGroupSize.x];
shared uint wg_sum_total;

// Exclusive prefix sum of `v` over the workgroup in invocation order (subgroup by subgroup, then
// lanes); `total` receives the workgroup's sum. Must be called in uniform control flow by every
// invocation. Sums wrap modulo 2^32. Subgroups are never assumed full or of a fixed size: the
// subgroup sums are scanned by subgroup 0 in chunks of gl_SubgroupSize.
uint wg_exclusive_add(uint v, out uint total) {
    uint inclusive = subgroupInclusiveAdd(v);
    uint sub_sum = subgroupAdd(v);
    if (subgroupElect()) {
        wg_subgroup_sums[gl_SubgroupID] = sub_sum;
    }
    barrier();
    if (gl_SubgroupID == 0u) {
        uint carry = 0u;
        for (uint first = 0u; first < gl_NumSubgroups; first += gl_SubgroupSize) {
            uint i = first + gl_SubgroupInvocationID;
            uint s = i < gl_NumSubgroups ? wg_subgroup_sums[i] : 0u;
            uint ex = subgroupExclusiveAdd(s);
            if (i < gl_NumSubgroups) {
                wg_subgroup_sums[i] = carry + ex;
            }
            carry += subgroupAdd(s);
        }
        if (subgroupElect()) {
            wg_sum_total = carry;
        }
    }
    barrier();
    uint result = wg_subgroup_sums[gl_SubgroupID] + inclusive - v;
    total = wg_sum_total;
    // The shared sums may be reused by the next call.
    barrier();
    return result;
}
