#version 330 core
// rendiff's Lambert pass (pyrender_backend.py): world position and the flat face normal.
layout(location = 0) in vec3 position;
#ifdef NORMAL_LOC
layout(location = NORMAL_LOC) in vec3 normal;
#endif
layout(location = INST_M_LOC) in mat4 inst_m;

uniform mat4 M;
uniform mat4 V;
uniform mat4 P;

out vec3 frag_position;
out vec3 frag_normal;

void main()
{
    mat4 MI = M * inst_m;  // identity for rendiff's meshes: vertices are already in world space
    gl_Position = P * V * MI * vec4(position, 1.0);
    frag_position = vec3(MI * vec4(position, 1.0));
#ifdef NORMAL_LOC
    frag_normal = vec3(transpose(inverse(MI)) * vec4(normal, 0.0));
#else
    frag_normal = vec3(0.0);
#endif
}
