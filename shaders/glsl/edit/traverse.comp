#version 460
// Edit, top-down, one invocation per node of an inner level inside the tool's reach
// (push.level >= 1). Per child the tool (edit_tool(), push.material, region push.shape /
// push.tool) decides: keep the existing child when no voxel of it can change (outside the
// region, or a homogeneous child the tool cannot change: full of the added / painted material,
// empty under remove / paint, full under fill / copy, which only fill empty voxels); fill
// (EDIT_FULL | material) or clear (EDIT_EMPTY) when add / remove / paint covers every voxel
// (paint only of a uniform child: it keeps the geometry); else subdivide (append the child to
// the next level's entries).
//   src      entries (uvec4: min corner xyz in voxels, the existing value there)
//   dst      temporary nodes (8 child values; EDIT_TEMP | j names next entry j)
//   dst2     next level's entries; counters[0..4] = their count and the indirect dispatch
//            arguments of the next level's pass (x = its workgroups of 64, y = z = 1: the host
//            sets them to 1), so that the levels can be recorded into one submission
//   count_at this level's count (counters of the level above) when recorded that way
#include "edit/common.glsl"
#include "edit/traverse_level.glsl"
layout(local_size_x = 64) in;

void main() {
    edit_traverse_level(gl_GlobalInvocationID.x, gl_NumWorkGroups.x * 64u, edit_count());
}
