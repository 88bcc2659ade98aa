#version 460
// After the level's inserts: every EDIT_PENDING result becomes the NodePtr of its item's
// representative. dst = results, dst2 = result index (EDIT_FLAG_RESULT_INDEX),
// tables = the level's address buffer, whose missing counter counts items left without a
// handle (their results stay EDIT_PENDING, so that the pass can run again once a later insert
// round placed them).
#include "edit/common.glsl"
#include "edit/resolve_pass.glsl"
layout(local_size_x = 64) in;

void main() {
    edit_resolve_pass(gl_GlobalInvocationID.x, gl_NumWorkGroups.x * 64u);
}
