// The selection's appends (select.comp.glsl includes this after its buffers and counters): a slot in an
// item's counter, in its leaf list, and sums into the frame's counters, with one atomic per subgroup
// where the GL has subgroup ballots, else one per invocation.
#if defined(GL_ARB_shader_ballot) && defined(GL_ARB_gpu_shader_int64)
// Appends of the invocations running together are counted once per subgroup: one atomic from the lowest
// live invocation reserves room for all of them (each gets its rank among the live ones).
uint live_count(uint64_t m) { uvec2 v = unpackUint2x32(m); return uint(bitCount(v.x) + bitCount(v.y)); }

// True in the lowest live invocation of the subgroup, the one that makes the atomic for all of them.
bool leads(uint64_t live) {
    uvec2 lv = unpackUint2x32(live);
    return gl_SubGroupInvocationARB == (lv.x != 0u ? uint(findLSB(lv.x)) : 32u + uint(findLSB(lv.y)));
}

// This invocation's slot from the base the leader reserved: its rank among the live invocations.
uint slot(uint64_t live, uint base) { return readFirstInvocationARB(base) + live_count(live & gl_SubGroupLtMaskARB); }

// A slot in the item's counter cmd[word] for every live invocation (a work group is one item's); ``also``
// (>= 0) gets 24 indices a slot added.
uint reserve(int word, int also, int total) {
    uint64_t live = ballotARB(true);
    uint n = live_count(live), base = 0u;
    if (leads(live)) {
        base = atomicAdd(cmd[CMD0 + word], n);
        if (also >= 0) atomicAdd(cmd[CMD0 + also], LEAF_INDICES * n);     // the indexed draw: LEAF_INDICES a leaf
        if (total >= 0) atomicAdd(frame_count[total], n);
    }
    return slot(live, base);
}

// A slot in the item's leaf list for every live invocation.
uint reserve_found() {
    uint64_t live = ballotARB(true);
    uint n = live_count(live), base = 0u;
    if (leads(live)) base = atomicAdd(cmd[CMD0 + FOUND_WORD], n);
    return slot(live, base);
}

// Adds v of every live invocation to frame_count[word] with one atomic per subgroup.
void add_total(int word, uint v) {
    uint64_t live = ballotARB(true);
    uint sum = 0u;
    for (uint i = 0u; i < gl_SubGroupSizeARB; i++) {
        uint x = readInvocationARB(v, i);
        if (((live >> i) & 1ul) != 0ul) sum += x;
    }
    if (leads(live)) atomicAdd(frame_count[word], sum);
}
#else
uint reserve(int word, int also, int total) {
    if (also >= 0) atomicAdd(cmd[CMD0 + also], LEAF_INDICES);
    if (total >= 0) atomicAdd(frame_count[total], 1u);
    return atomicAdd(cmd[CMD0 + word], 1u);
}

void add_total(int word, uint v) { atomicAdd(frame_count[word], v); }

uint reserve_found() { return atomicAdd(cmd[CMD0 + FOUND_WORD], 1u); }
#endif
