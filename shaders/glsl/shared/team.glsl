// Subgroup teams: the lanes that work on one item together, shared by the cooperative passes
// (hash search/insert/GC, dedup). Define `TEAM` first: the subgroup size (workgroups are whole
// subgroups) or 1 (every lane its own item). With TEAM == 1 every helper is a plain value and the
// subgroup branches are removed at specialization. Team indices derive from the workgroup size, not gl_NumSubgroups (lavapipe's own
// value was unreliable).
#ifndef VOXDAG_SHARED_TEAM_GLSL
#define VOXDAG_SHARED_TEAM_GLSL

#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_ballot : require
#extension GL_KHR_shader_subgroup_vote : require
#extension GL_KHR_shader_subgroup_arithmetic : require

// The team's lane index.
uint team_lane() {
    return TEAM == 1u ? 0u : gl_SubgroupInvocationID;
}

// Whether this lane is the team's leader (the one that runs scalar sections).
bool team_leader() {
    if (TEAM == 1u) return true;
    return subgroupElect();
}

// The leader's value, in every lane of the team.
uint team_from_leader(uint v) {
    if (TEAM == 1u) return v;
    return subgroupBroadcastFirst(v);
}

bool team_any(bool b) {
    if (TEAM == 1u) return b;
    return subgroupAny(b);
}

// Lowest team lane where b holds (only call when team_any(b)).
uint team_first(bool b) {
    if (TEAM == 1u) return 0u;
    return subgroupBallotFindLSB(subgroupBallot(b));
}

uint team_min(uint v) {
    if (TEAM == 1u) return v;
    return subgroupMin(v);
}

// Index of this lane's team among all teams of the dispatch, and the number of teams.
uint team_index() {
    uint per_group = gl_WorkGroupSize.x / TEAM;
    uint in_group = TEAM == 1u ? gl_LocalInvocationIndex : gl_SubgroupID;
    return gl_WorkGroupID.x * per_group + in_group;
}

uint team_count() {
    return gl_NumWorkGroups.x * (gl_WorkGroupSize.x / TEAM);
}

#endif
