// resolve's body (edit/resolve.comp; also run for the root level by
// edit/merge_small_levels.comp). The includer includes edit/common.glsl first.

// Resolves the pending results of nodes start, start + stride, ... of the level (`push`).
void edit_resolve_pass(uint start, uint stride) {
    Words results = Words(push.dst);
    Addresses tables = Addresses(push.tables);
    Words slots = Words(tables.a[EDIT_LEVEL_SLOTS]);
    EditLevelHandles level = edit_level_handles(tables);
    // The exit test at the loop's end (docs/gpu.md, "Loops on lavapipe").
    uint i = start;
    if (i < push.count) for (;;) {
        uint at = (push.flags & EDIT_FLAG_RESULT_INDEX) != 0u ? Words(push.dst2).w[i] : i;
        uint r = results.w[at];
        if ((r & EDIT_TAG_MASK) == EDIT_PENDING) {
            uint v = edit_resolve_slot(level, slots.w[i], r);
            if (v == r) {
                atomicAdd(Words(tables.a[EDIT_LEVEL_MISSING]).w[0], 1u);
            }
            results.w[at] = v;
        }
        i += stride;
        if (i >= push.count) break;
    }
}
