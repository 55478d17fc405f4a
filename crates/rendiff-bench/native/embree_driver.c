/* A native Embree 3 application for primary rays, as small as it can be:
 * what `rendiff bench peers` compares its Embree numbers with, so that the
 * bench cannot report Embree below its best without saying so
 * (docs/embree-fastest-path.md).
 *
 * It is C compiled against Embree's own headers (rtcore.h), so the ray and
 * hit layouts are Embree's, not a transcription. The caller prepares every
 * ray in f32 once (origin, direction, tnear, tfar per pixel, row-major) and
 * times `rd_trace_strip` calls; each call copies its rays into Embree's
 * layout for the chosen entry point (RTCRayHit, RTCRayHit4/8/16, a stream of
 * RTCRayHit or of RTCRayHitN packets), traces them, and writes the hit
 * distance and primitive ID of every pixel. Flush-to-zero and
 * denormals-are-zero are set in MXCSR for the call, as Embree's
 * documentation recommends for every thread that traces, and the caller's
 * MXCSR is restored before returning (the caller is Rust, whose code must
 * not run with a changed floating-point environment).
 */
#include <embree3/rtcore.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#if defined(__SSE__) || defined(__x86_64__)
#include <pmmintrin.h>
#include <xmmintrin.h>
#define RD_HAVE_MXCSR 1
#endif

/* Entry points, in the order of `Entry` in native_embree.rs. */
enum {
  RD_1 = 0,   /* rtcIntersect1 per pixel */
  RD_4 = 1,   /* rtcIntersect4 on 2x2 tiles */
  RD_8 = 2,   /* rtcIntersect8 on 4x2 tiles */
  RD_16 = 3,  /* rtcIntersect16 on 4x4 tiles */
  RD_1M = 4,  /* rtcIntersect1M, RTCRayHit in 4x4-tile order */
  RD_NM4 = 5, /* rtcIntersectNM, N = 4, 2x2 tiles */
  RD_NM8 = 6, /* rtcIntersectNM, N = 8, 4x2 tiles */
  RD_NM16 = 7 /* rtcIntersectNM, N = 16, 4x4 tiles */
};

/* Rays per stream call: 80 KiB of RTCRayHit, which stays in L2 between
 * writing the rays and reading the hits. */
#define RD_STREAM_RAYS 1024

/* The prepared rays of one frame (f32, one per pixel, row-major). */
typedef struct {
  uint32_t width, height;
  float org[3];
  const float *dx, *dy, *dz, *tnear, *tfar;
} rd_rays;

/* A device and its committed scene. */
typedef struct {
  RTCDevice device;
  RTCScene scene;
} rd_scene;

static void rd_error(char *err, size_t len, const char *what, RTCDevice d) {
  enum RTCError e = rtcGetDeviceError(d);
  snprintf(err, len, "%s failed (RTCError %d)", what, (int)e);
}

/* Embree's version as major*10000 + minor*100 + patch. */
long rd_version(void) {
  RTCDevice d = rtcNewDevice("threads=1");
  if (!d) return -1;
  long v = (long)rtcGetDeviceProperty(d, RTC_DEVICE_PROPERTY_VERSION);
  rtcReleaseDevice(d);
  return v;
}

/* Builds a scene of `n` triangles (9 floats each, unshared vertices, primID =
 * index) with build quality 0/1/2 = LOW/MEDIUM/HIGH; `robust` sets
 * RTC_SCENE_FLAG_ROBUST. The device gets `threads` threads for the build.
 * Returns NULL with a message in `err` on failure. */
rd_scene *rd_build(const float *tri, size_t n, int quality, int robust, unsigned threads,
                   char *err, size_t err_len) {
  char config[64];
  snprintf(config, sizeof config, "threads=%u", threads ? threads : 1u);
  RTCDevice d = rtcNewDevice(config);
  if (!d) {
    snprintf(err, err_len, "rtcNewDevice(\"%s\") failed (RTCError %d)", config,
             (int)rtcGetDeviceError(NULL));
    return NULL;
  }
  if (rtcGetDeviceProperty(d, RTC_DEVICE_PROPERTY_BACKFACE_CULLING_ENABLED)) {
    snprintf(err, err_len, "this libembree3 culls back faces, which docs/DESIGN.md forbids");
    rtcReleaseDevice(d);
    return NULL;
  }
  RTCScene s = rtcNewScene(d);
  rtcSetSceneFlags(s, robust ? RTC_SCENE_FLAG_ROBUST : RTC_SCENE_FLAG_NONE);
  enum RTCBuildQuality q = quality == 0   ? RTC_BUILD_QUALITY_LOW
                           : quality == 2 ? RTC_BUILD_QUALITY_HIGH
                                          : RTC_BUILD_QUALITY_MEDIUM;
  rtcSetSceneBuildQuality(s, q);
  if (n > 0) {
    RTCGeometry g = rtcNewGeometry(d, RTC_GEOMETRY_TYPE_TRIANGLE);
    rtcSetGeometryBuildQuality(g, q);
    float *v = (float *)rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                                3 * sizeof(float), 3 * n);
    unsigned *ix = (unsigned *)rtcSetNewGeometryBuffer(g, RTC_BUFFER_TYPE_INDEX, 0,
                                                       RTC_FORMAT_UINT3, 3 * sizeof(unsigned), n);
    if (!v || !ix) {
      rd_error(err, err_len, "rtcSetNewGeometryBuffer", d);
      rtcReleaseGeometry(g);
      rtcReleaseScene(s);
      rtcReleaseDevice(d);
      return NULL;
    }
    memcpy(v, tri, 9 * n * sizeof(float));
    for (size_t i = 0; i < 3 * n; i++) ix[i] = (unsigned)i;
    rtcCommitGeometry(g);
    rtcAttachGeometry(s, g);
    rtcReleaseGeometry(g);
  }
  rtcCommitScene(s);
  if (rtcGetDeviceError(d) != RTC_ERROR_NONE) {
    rd_error(err, err_len, "building the scene", d);
    rtcReleaseScene(s);
    rtcReleaseDevice(d);
    return NULL;
  }
  rd_scene *out = (rd_scene *)malloc(sizeof *out);
  if (!out) {
    snprintf(err, err_len, "out of memory");
    rtcReleaseScene(s);
    rtcReleaseDevice(d);
    return NULL;
  }
  out->device = d;
  out->scene = s;
  return out;
}

void rd_release(rd_scene *s) {
  if (!s) return;
  rtcReleaseScene(s->scene);
  rtcReleaseDevice(s->device);
  free(s);
}

/* Writes one traced ray's result for pixel `p`: distance and primID, or
 * (+inf, ~0) for a miss. */
static inline void rd_store(float *t_out, uint32_t *prim_out, size_t p, unsigned geom, float tfar,
                            unsigned prim) {
  int hit = geom != RTC_INVALID_GEOMETRY_ID;
  t_out[p] = hit ? tfar : INFINITY;
  prim_out[p] = hit ? prim : 0xffffffffu;
}

/* Packets of N on tiles `TW` wide (N / TW rows) over the rows [y0, y0 + rows)
 * with rtcIntersect<N>, lanes outside the image masked. */
#define RD_PACKETS(N, TW)                                                                    \
  static void rd_packets##N(RTCScene scene, struct RTCIntersectContext *ctx, const rd_rays *r, \
                            uint32_t y0, uint32_t rows, float *t_out, uint32_t *prim_out) {   \
    const uint32_t th = (N) / (TW), w = r->width;                                            \
    for (uint32_t ty = y0; ty < y0 + rows; ty += th)                                         \
      for (uint32_t tx = 0; tx < w; tx += (TW)) {                                            \
        RTC_ALIGN(64) int valid[N];                                                          \
        RTC_ALIGN(64) struct RTCRayHit##N rh;                                                \
        for (int i = 0; i < (N); i++) {                                                      \
          uint32_t x = tx + i % (TW), y = ty + i / (TW);                                     \
          int in = x < w && y < y0 + rows;                                                   \
          size_t p = (size_t)(in ? y : y0) * w + (in ? x : 0);                                             \
          valid[i] = in ? -1 : 0;                                                            \
          rh.ray.org_x[i] = r->org[0];                                                       \
          rh.ray.org_y[i] = r->org[1];                                                       \
          rh.ray.org_z[i] = r->org[2];                                                       \
          rh.ray.dir_x[i] = r->dx[p];                                                        \
          rh.ray.dir_y[i] = r->dy[p];                                                        \
          rh.ray.dir_z[i] = r->dz[p];                                                        \
          rh.ray.tnear[i] = r->tnear[p];                                                     \
          rh.ray.tfar[i] = r->tfar[p];                                                       \
          rh.ray.time[i] = 0.0f;                                                             \
          rh.ray.mask[i] = 0xffffffffu;                                                      \
          rh.ray.id[i] = 0;                                                                  \
          rh.ray.flags[i] = 0;                                                               \
          rh.hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;                                        \
          rh.hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;                                     \
        }                                                                                    \
        rtcIntersect##N(valid, scene, ctx, &rh);                                             \
        for (int i = 0; i < (N); i++) {                                                      \
          uint32_t x = tx + i % (TW), y = ty + i / (TW);                                     \
          if (x < w && y < y0 + rows)                                                        \
            rd_store(t_out, prim_out, (size_t)y * w + x, rh.hit.geomID[i], rh.ray.tfar[i],   \
                     rh.hit.primID[i]);                                                      \
        }                                                                                    \
      }                                                                                      \
  }
RD_PACKETS(4, 2)
RD_PACKETS(8, 4)
RD_PACKETS(16, 4)

/* Streams of RTCRayHit<N> packets (N / TW rows) with rtcIntersectNM; lanes
 * outside the image are inactive (tnear > tfar), as the stream API has no
 * valid mask. */
#define RD_STREAM_N(N, TW)                                                                     \
  static void rd_stream##N(RTCScene scene, struct RTCIntersectContext *ctx, const rd_rays *r,  \
                           uint32_t y0, uint32_t rows, float *t_out, uint32_t *prim_out) {    \
    enum { M = RD_STREAM_RAYS / (N) };                                                         \
    const uint32_t th = (N) / (TW), w = r->width;                                              \
    RTC_ALIGN(64) struct RTCRayHit##N rh[M];                                                   \
    uint32_t at_x[M], at_y[M];                                                                 \
    for (uint32_t ty = y0; ty < y0 + rows; ty += th) {                                         \
      uint32_t m = 0;                                                                          \
      for (uint32_t tx = 0; tx < w; tx += (TW)) {                                              \
        struct RTCRayHit##N *q = &rh[m];                                                       \
        at_x[m] = tx;                                                                          \
        at_y[m] = ty;                                                                          \
        for (int i = 0; i < (N); i++) {                                                        \
          uint32_t x = tx + i % (TW), y = ty + i / (TW);                                       \
          int in = x < w && y < y0 + rows;                                                     \
          size_t p = (size_t)(in ? y : y0) * w + (in ? x : 0);                                               \
          q->ray.org_x[i] = r->org[0];                                                         \
          q->ray.org_y[i] = r->org[1];                                                         \
          q->ray.org_z[i] = r->org[2];                                                         \
          q->ray.dir_x[i] = r->dx[p];                                                          \
          q->ray.dir_y[i] = r->dy[p];                                                          \
          q->ray.dir_z[i] = r->dz[p];                                                          \
          q->ray.tnear[i] = in ? r->tnear[p] : 1.0f;                                           \
          q->ray.tfar[i] = in ? r->tfar[p] : 0.0f;                                             \
          q->ray.time[i] = 0.0f;                                                               \
          q->ray.mask[i] = 0xffffffffu;                                                        \
          q->ray.id[i] = 0;                                                                    \
          q->ray.flags[i] = 0;                                                                 \
          q->hit.geomID[i] = RTC_INVALID_GEOMETRY_ID;                                          \
          q->hit.instID[0][i] = RTC_INVALID_GEOMETRY_ID;                                       \
        }                                                                                      \
        if (++m == M || tx + (TW) >= w) {                                                      \
          rtcIntersectNM(scene, ctx, (struct RTCRayHitN *)rh, (N), m, sizeof(rh[0]));          \
          for (uint32_t k = 0; k < m; k++)                                                     \
            for (int i = 0; i < (N); i++) {                                                    \
              uint32_t x = at_x[k] + i % (TW), y = at_y[k] + i / (TW);                         \
              if (x < w && y < y0 + rows)                                                      \
                rd_store(t_out, prim_out, (size_t)y * w + x, rh[k].hit.geomID[i],              \
                         rh[k].ray.tfar[i], rh[k].hit.primID[i]);                              \
            }                                                                                  \
          m = 0;                                                                               \
        }                                                                                      \
      }                                                                                        \
    }                                                                                          \
  }
RD_STREAM_N(4, 2)
RD_STREAM_N(8, 4)
RD_STREAM_N(16, 4)

static void rd_single(RTCScene scene, struct RTCIntersectContext *ctx, const rd_rays *r,
                      uint32_t y0, uint32_t rows, float *t_out, uint32_t *prim_out) {
  const uint32_t w = r->width;
  for (uint32_t y = y0; y < y0 + rows; y++)
    for (uint32_t x = 0; x < w; x++) {
      size_t p = (size_t)y * w + x;
      struct RTCRayHit rh;
      rh.ray.org_x = r->org[0];
      rh.ray.org_y = r->org[1];
      rh.ray.org_z = r->org[2];
      rh.ray.dir_x = r->dx[p];
      rh.ray.dir_y = r->dy[p];
      rh.ray.dir_z = r->dz[p];
      rh.ray.tnear = r->tnear[p];
      rh.ray.tfar = r->tfar[p];
      rh.ray.time = 0.0f;
      rh.ray.mask = 0xffffffffu;
      rh.ray.id = 0;
      rh.ray.flags = 0;
      rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
      rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
      rtcIntersect1(scene, ctx, &rh);
      rd_store(t_out, prim_out, p, rh.hit.geomID, rh.ray.tfar, rh.hit.primID);
    }
}

/* rtcIntersect1M over RTCRayHit laid out tile by tile (4x4 pixels, row-major
 * inside a tile), so the packets Embree forms from consecutive rays are
 * compact tiles. */
static void rd_stream1(RTCScene scene, struct RTCIntersectContext *ctx, const rd_rays *r,
                       uint32_t y0, uint32_t rows, float *t_out, uint32_t *prim_out) {
  const uint32_t w = r->width;
  RTC_ALIGN(16) struct RTCRayHit rh[RD_STREAM_RAYS];
  size_t at[RD_STREAM_RAYS];
  for (uint32_t ty = y0; ty < y0 + rows; ty += 4) {
    uint32_t m = 0;
    for (uint32_t tx = 0; tx < w; tx += 4) {
      for (uint32_t y = ty; y < ty + 4 && y < y0 + rows; y++)
        for (uint32_t x = tx; x < tx + 4 && x < w; x++) {
          size_t p = (size_t)y * w + x;
          struct RTCRayHit *q = &rh[m];
          at[m++] = p;
          q->ray.org_x = r->org[0];
          q->ray.org_y = r->org[1];
          q->ray.org_z = r->org[2];
          q->ray.dir_x = r->dx[p];
          q->ray.dir_y = r->dy[p];
          q->ray.dir_z = r->dz[p];
          q->ray.tnear = r->tnear[p];
          q->ray.tfar = r->tfar[p];
          q->ray.time = 0.0f;
          q->ray.mask = 0xffffffffu;
          q->ray.id = 0;
          q->ray.flags = 0;
          q->hit.geomID = RTC_INVALID_GEOMETRY_ID;
          q->hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
        }
      if (m + 16 > RD_STREAM_RAYS || tx + 4 >= w) {
        rtcIntersect1M(scene, ctx, rh, m, sizeof(rh[0]));
        for (uint32_t k = 0; k < m; k++)
          rd_store(t_out, prim_out, at[k], rh[k].hit.geomID, rh[k].ray.tfar, rh[k].hit.primID);
        m = 0;
      }
    }
  }
}

/* Traces the image rows [y0, y0 + rows) of `r` through `s` with entry point
 * `entry` (RD_*) and the coherent (1) or incoherent (0) context flag, writing
 * `t_out[p]` and `prim_out[p]` for every pixel p of those rows. Reads the
 * rays of those rows only (a packet's lanes outside them read the rows'
 * first ray, masked), so `r` may hold just them (the caller's strip of rays
 * made for these rows, its pointers moved back y0 rows). `rows` must
 * be a multiple of 4 except at the bottom of the image. Thread-safe for
 * disjoint row ranges. Returns 0, or -1 for an unknown entry point. */
int rd_trace_strip(const rd_scene *s, const rd_rays *r, int entry, int coherent, uint32_t y0,
                   uint32_t rows, float *t_out, uint32_t *prim_out) {
#ifdef RD_HAVE_MXCSR
  unsigned int saved = _mm_getcsr();
  _MM_SET_FLUSH_ZERO_MODE(_MM_FLUSH_ZERO_ON);
  _MM_SET_DENORMALS_ZERO_MODE(_MM_DENORMALS_ZERO_ON);
#endif
  struct RTCIntersectContext ctx;
  rtcInitIntersectContext(&ctx);
  ctx.flags = coherent ? RTC_INTERSECT_CONTEXT_FLAG_COHERENT : RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT;
  int rc = 0;
  switch (entry) {
  case RD_1: rd_single(s->scene, &ctx, r, y0, rows, t_out, prim_out); break;
  case RD_4: rd_packets4(s->scene, &ctx, r, y0, rows, t_out, prim_out); break;
  case RD_8: rd_packets8(s->scene, &ctx, r, y0, rows, t_out, prim_out); break;
  case RD_16: rd_packets16(s->scene, &ctx, r, y0, rows, t_out, prim_out); break;
  case RD_1M: rd_stream1(s->scene, &ctx, r, y0, rows, t_out, prim_out); break;
  case RD_NM4: rd_stream4(s->scene, &ctx, r, y0, rows, t_out, prim_out); break;
  case RD_NM8: rd_stream8(s->scene, &ctx, r, y0, rows, t_out, prim_out); break;
  case RD_NM16: rd_stream16(s->scene, &ctx, r, y0, rows, t_out, prim_out); break;
  default: rc = -1;
  }
#ifdef RD_HAVE_MXCSR
  _mm_setcsr(saved);
#endif
  return rc;
}
