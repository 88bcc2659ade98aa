// The DAG format's info block and tables (`GpuDagData::info`, engine/render/format.rs): the
// level records, Huffman decode tables and pointer tables of the encoded formats, the table
// addresses of the hash DAG. Read at indices that differ per invocation, so they are a uniform
// texel buffer (word pairs, `R32G32_UINT`) rather than a buffer address: lavapipe fetches texels
// for all SIMD lanes at once but loads through an address one lane at a time, in a loop with a
// branch per lane (docs/pathtracing.md, "Format tables as texels").
//
// The includer defines DAG_TABLES_BINDING (the binding in set 0) before including this file.
#ifndef VOXDAG_RENDER_DAG_TABLES_GLSL
#define VOXDAG_RENDER_DAG_TABLES_GLSL

layout(set = 0, binding = DAG_TABLES_BINDING) uniform usamplerBuffer dag_tables;

// Word i of the info block.
uint dag_info(uint i) {
    uvec2 pair = texelFetch(dag_tables, int(i >> 1u)).xy;
    return (i & 1u) != 0u ? pair.y : pair.x;
}

// Words i and i + 1 of the info block, i even: one texel.
#define DAG_HAS_INFO_PAIR 1
uvec2 dag_info_pair(uint i) {
    return texelFetch(dag_tables, int(i >> 1u)).xy;
}

#endif
