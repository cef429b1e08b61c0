// Appends of raster/select.comp.glsl: slots in its counters (cmd[], found[]) and sums into frame_count[], one
// atomic a subgroup where the ballot extensions are there, else one an invocation. Included after the buffers.
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

// A slot in counter cmd[word] for every live invocation; ``also`` (>= 0) gets 24 indices a slot added.
uint reserve(int word, int also, int total) {
    uint64_t live = ballotARB(true);
    uint n = live_count(live), base = 0u;
    if (leads(live)) {
        base = atomicAdd(cmd[word], n);
        if (also >= 0) atomicAdd(cmd[also], 24u * n);     // the indexed draw: 24 indices a leaf
        if (total >= 0) atomicAdd(frame_count[total], n);
    }
    return slot(live, base);
}

// A slot in the leaf list for every live invocation; keeps the pass-1 work group count (x) up to date.
uint reserve_found() {
    uint64_t live = ballotARB(true);
    uint n = live_count(live), base = 0u;
    if (leads(live)) {
        base = atomicAdd(found[3], n);
        atomicMax(found[0], (base + n + 63u) / 64u);
    }
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
    if (also >= 0) atomicAdd(cmd[also], 24u);
    if (total >= 0) atomicAdd(frame_count[total], 1u);
    return atomicAdd(cmd[word], 1u);
}

void add_total(int word, uint v) { atomicAdd(frame_count[word], v); }

uint reserve_found() {
    uint base = atomicAdd(found[3], 1u);
    atomicMax(found[0], (base + 64u) / 64u);
    return base;
}
#endif
