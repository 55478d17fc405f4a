#version 330 core
// rendiff's Lambert pass (pyrender_backend.py): docs/radiance.md's local shading, two-sided,
// shadowless, written as (L / S)^(1/2.2) to the 8-bit framebuffer. The exposure 1/S is folded
// into the light intensities and the emissive factor by the backend.
//   L = Le + sum_dir rho/pi E max(0, n.(-dir)) + sum_point rho/pi I max(0, n.w)/r^2
// pyrender binds these uniforms itself (renderer._bind_lighting, _bind_and_draw_primitive).

struct DirectionalLight {
    vec3 direction;
    vec3 color;
    float intensity;
};

struct PointLight {
    vec3 position;
    vec3 color;
    float intensity;
};

struct Material {
    vec3 emissive_factor;
    vec4 base_color_factor;
    float metallic_factor;
    float roughness_factor;
};

uniform Material material;
uniform int n_directional_lights;
uniform int n_point_lights;
uniform DirectionalLight directional_lights[MAX_DIRECTIONAL_LIGHTS];
uniform PointLight point_lights[MAX_POINT_LIGHTS];
uniform vec3 cam_pos;

in vec3 frag_position;
in vec3 frag_normal;

out vec4 frag_color;

const float INV_PI = 0.31830988618379067;

void main()
{
    vec3 n = normalize(frag_normal);
    if (dot(n, cam_pos - frag_position) < 0.0) {
        n = -n;  // two-sided: the normal turned toward the viewer
    }
    vec3 rho = material.base_color_factor.rgb;
    vec3 L = material.emissive_factor;
    for (int i = 0; i < n_directional_lights; i++) {
        float c = max(0.0, dot(n, -directional_lights[i].direction));
        L += rho * INV_PI * (directional_lights[i].color * directional_lights[i].intensity) * c;
    }
    for (int i = 0; i < n_point_lights; i++) {
        vec3 d = point_lights[i].position - frag_position;
        float r2 = dot(d, d);
        float c = max(0.0, dot(n, d) * inversesqrt(r2));
        L += rho * INV_PI * (point_lights[i].color * point_lights[i].intensity) * (c / r2);
    }
    frag_color = vec4(pow(clamp(L, 0.0, 1.0), vec3(1.0 / 2.2)), 1.0);
}
