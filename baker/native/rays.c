/* Embree's ray queries for baker, called through ctypes (baker/rays/native.py).
 *
 * embreex casts each ray from a Cython loop that reads numpy buffers item by item and fills
 * eight result arrays, and copies a scene's vertices one by one through Python; this file
 * reads and writes plain float32/int32 rows and asks Embree the same questions (rtcIntersect1,
 * rtcOccluded1, default arguments) of the same library (the libembree4 that embreex's wheel
 * ships, loaded by native.py before this file): 1.04-1.10x embreex's rate on nearest hits, a
 * scene built 5x faster, and occlusion in packets of 16 rays on an AVX-512 CPU, of 8 with
 * AVX2 (benchmarks/bench_rays.py). The library is not linked here: its symbols are resolved when
 * native.py loads this file, so that the install needs only a C compiler, no headers.
 *
 * The declarations below are those of Embree 4's public headers (include/embree4/, Apache
 * License 2.0, Copyright Intel Corporation), only what is used. A hit is given room past its
 * declared end: a library built with instance arrays writes one more field there.
 */

#include <stddef.h>
#include <stdlib.h>

typedef struct RTCDeviceTy *RTCDevice;
typedef struct RTCSceneTy *RTCScene;
typedef struct RTCGeometryTy *RTCGeometry;

enum { RTC_GEOMETRY_TYPE_TRIANGLE = 0 };
enum { RTC_BUFFER_TYPE_INDEX = 0, RTC_BUFFER_TYPE_VERTEX = 1 };
enum { RTC_FORMAT_UINT3 = 0x5003, RTC_FORMAT_FLOAT3 = 0x9003 };
enum { RTC_SCENE_FLAG_ROBUST = 1 << 2 };
#define RTC_INVALID_GEOMETRY_ID ((unsigned int)-1)

struct __attribute__((aligned(16))) RTCRay {
    float org_x, org_y, org_z, tnear;
    float dir_x, dir_y, dir_z, time;
    float tfar;
    unsigned int mask, id, flags;
};

struct __attribute__((aligned(16))) RTCHit {
    float Ng_x, Ng_y, Ng_z;
    float u, v;
    unsigned int primID, geomID;
    unsigned int instID[1];
};

struct __attribute__((aligned(16))) RTCRayHit {
    struct RTCRay ray;
    struct RTCHit hit;
    unsigned int spare[8];  /* instPrimID where the library has it */
};

RTCDevice rtcNewDevice(const char *config);
void rtcReleaseDevice(RTCDevice device);
int rtcGetDeviceError(RTCDevice device);
RTCScene rtcNewScene(RTCDevice device);
void rtcReleaseScene(RTCScene scene);
void rtcCommitScene(RTCScene scene);
void rtcSetSceneFlags(RTCScene scene, int flags);
RTCGeometry rtcNewGeometry(RTCDevice device, int type);
void *rtcSetNewGeometryBuffer(RTCGeometry geometry, int type, unsigned int slot, int format,
                              size_t byteStride, size_t itemCount);
void rtcCommitGeometry(RTCGeometry geometry);
unsigned int rtcAttachGeometry(RTCScene scene, RTCGeometry geometry);
void rtcReleaseGeometry(RTCGeometry geometry);
void rtcIntersect1(RTCScene scene, struct RTCRayHit *rayhit, void *args);
void rtcOccluded1(RTCScene scene, struct RTCRay *ray, void *args);

/* N rays, a row each (Embree's RTCRay8, RTCRay16), for rtcOccluded8 and rtcOccluded16. */
#define RAY_PACKET(N)                                                                          \
    struct __attribute__((aligned(4 * N))) RTCRay##N {                                         \
        float org_x[N], org_y[N], org_z[N], tnear[N];                                          \
        float dir_x[N], dir_y[N], dir_z[N], time[N];                                           \
        float tfar[N];                                                                         \
        unsigned int mask[N], id[N], flags[N];                                                 \
    };                                                                                         \
    void rtcOccluded##N(const int *valid, RTCScene scene, struct RTCRay##N *ray, void *args);
RAY_PACKET(8)
RAY_PACKET(16)

/* A device and its one scene. */
typedef struct {
    RTCDevice device;
    RTCScene scene;
} Traced;

void baker_release(Traced *traced);
int baker_packets(void);

/* The scene of one triangle mesh: vertices (nv, 3) float32, triangles (nt, 3) int32 rows
 * into them, built as embreex builds it (vertices 16 bytes apart, RTC_SCENE_FLAG_ROBUST: its
 * watertight test, which also meets a surface through the ray's origin); NULL if Embree fails.
 * Released by baker_release. */
Traced *baker_scene(const float *vertices, long nv, const int *triangles, long nt)
{
    Traced *traced;
    RTCGeometry geometry;
    float *v;
    unsigned int *t;
    long i;
    RTCDevice device = rtcNewDevice(NULL);
    if (device == NULL)
        return NULL;
    geometry = rtcNewGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
    v = rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3,
                                4 * sizeof(float), (size_t)nv);
    t = rtcSetNewGeometryBuffer(geometry, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3,
                                3 * sizeof(unsigned int), (size_t)nt);
    traced = malloc(sizeof(Traced));
    if (geometry == NULL || v == NULL || t == NULL || traced == NULL) {
        free(traced);
        if (geometry != NULL)
            rtcReleaseGeometry(geometry);
        rtcReleaseDevice(device);
        return NULL;
    }
    for (i = 0; i < nv; i++) {
        v[4 * i] = vertices[3 * i];
        v[4 * i + 1] = vertices[3 * i + 1];
        v[4 * i + 2] = vertices[3 * i + 2];
        v[4 * i + 3] = 0.0f;
    }
    for (i = 0; i < 3 * nt; i++)
        t[i] = (unsigned int)triangles[i];
    rtcCommitGeometry(geometry);
    traced->device = device;
    traced->scene = rtcNewScene(device);
    rtcSetSceneFlags(traced->scene, RTC_SCENE_FLAG_ROBUST);
    rtcAttachGeometry(traced->scene, geometry);
    rtcReleaseGeometry(geometry);
    rtcCommitScene(traced->scene);
    if (rtcGetDeviceError(device) != 0) {
        baker_release(traced);
        return NULL;
    }
    return traced;
}

void baker_release(Traced *traced)
{
    if (traced == NULL)
        return;
    if (traced->scene != NULL)
        rtcReleaseScene(traced->scene);
    rtcReleaseDevice(traced->device);
    free(traced);
}

/* Nearest hits of n rays: origins and directions (n, 3) float32, lengths (n,) float32,
 * overwritten with the hit distance (kept for a miss); triangle (n,) int32 the hit's triangle
 * (-1 for a miss), u, v (n,) float32 its barycentric weights, as embreex's run(output=1).
 * near: NULL, or (n,) float32 where along each ray its search starts (Embree's tnear): a ray
 * let through a see-through hit goes on along its own line from just past it, so the path a
 * bake traces is the straight ray the rebake's searches test (embreex sets no tnear). */
void baker_nearest(const Traced *traced, const float *origins, const float *directions,
                   const float *near, float *lengths, long n, int *triangle, float *u, float *v)
{
    struct RTCRayHit rh;
    long i;
    for (i = 0; i < n; i++) {
        rh.ray.org_x = origins[3 * i];
        rh.ray.org_y = origins[3 * i + 1];
        rh.ray.org_z = origins[3 * i + 2];
        rh.ray.tnear = near == NULL ? 0.0f : near[i];
        rh.ray.dir_x = directions[3 * i];
        rh.ray.dir_y = directions[3 * i + 1];
        rh.ray.dir_z = directions[3 * i + 2];
        rh.ray.time = 0.0f;
        rh.ray.tfar = lengths[i];
        rh.ray.mask = 0xFFFFFFFFu;
        rh.ray.id = 0;
        rh.ray.flags = 0;
        rh.hit.primID = rh.hit.geomID = rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
        rtcIntersect1(traced->scene, &rh, NULL);
        if (rh.hit.geomID == RTC_INVALID_GEOMETRY_ID) {
            triangle[i] = -1;
            u[i] = v[i] = 0.0f;
        } else {
            triangle[i] = (int)rh.hit.primID;
            lengths[i] = rh.ray.tfar;
            u[i] = rh.hit.u;
            v[i] = rh.hit.v;
        }
    }
}

/* Every lane of a packet live (Embree's valid mask), for packets of up to 16 rays. */
static const int __attribute__((aligned(64))) LIVE[16] = {
    -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1};

/* baker_occluded's answers for the first whole packets of N of its n rays, each packet cast
 * by rtcOccluded8 or rtcOccluded16 with every lane live; returns how many rays were cast. */
#define OCCLUDED_PACKETS(N)                                                                    \
    static long occluded_packets##N(const Traced *traced, const float *origins,                \
                                    const float *directions, const float *lengths, long n,     \
                                    int *blocked)                                              \
    {                                                                                          \
        struct RTCRay##N packet;                                                               \
        long i, j;                                                                             \
        for (i = 0; i + N <= n; i += N) {                                                      \
            for (j = 0; j < N; j++) {                                                          \
                packet.org_x[j] = origins[3 * (i + j)];                                        \
                packet.org_y[j] = origins[3 * (i + j) + 1];                                    \
                packet.org_z[j] = origins[3 * (i + j) + 2];                                    \
                packet.tnear[j] = 0.0f;                                                        \
                packet.dir_x[j] = directions[3 * (i + j)];                                     \
                packet.dir_y[j] = directions[3 * (i + j) + 1];                                 \
                packet.dir_z[j] = directions[3 * (i + j) + 2];                                 \
                packet.time[j] = 0.0f;                                                         \
                packet.tfar[j] = lengths[i + j];                                               \
                packet.mask[j] = 0xFFFFFFFFu;                                                  \
                packet.id[j] = 0;                                                              \
                packet.flags[j] = 0;                                                           \
            }                                                                                  \
            rtcOccluded##N(LIVE, traced->scene, &packet, NULL);                                \
            for (j = 0; j < N; j++)                                                            \
                blocked[i + j] = packet.tfar[j] < 0.0f ? 0 : -1;                               \
        }                                                                                      \
        return i;                                                                              \
    }
OCCLUDED_PACKETS(8)
OCCLUDED_PACKETS(16)

/* Whether anything lies along each of n rays (as baker_nearest takes them; lengths kept):
 * blocked (n,) int32 0 where something does, -1 where nothing does, as embreex's OCCLUDED.
 *
 * Whole runs of consecutive rays go to Embree as one packet where the CPU traces a packet's
 * lanes at once (baker_packets: 16 with AVX-512, 8 with AVX2), the rest one by one. A
 * packet's rays share the traversal of the nodes they all enter: on a bake's obscurance rays
 * (64 consecutive rays are one texel's, from one point) 1.3-1.5x the rate of single rays with
 * 16 on AVX-512, 1.3-1.4x with 8 on an AVX2 EPYC (benchmarks/bench_rays.py). Each ray's answer
 * is its own, whatever rays share its packet: the same as rtcOccluded1's
 * (tests/test_native_rays.py). */
void baker_occluded(const Traced *traced, const float *origins, const float *directions,
                    const float *lengths, long n, int *blocked)
{
    struct RTCRay ray;
    int width = baker_packets();
    long i = width == 16 ? occluded_packets16(traced, origins, directions, lengths, n, blocked)
           : width == 8  ? occluded_packets8(traced, origins, directions, lengths, n, blocked)
                         : 0;
    for (; i < n; i++) {
        ray.org_x = origins[3 * i];
        ray.org_y = origins[3 * i + 1];
        ray.org_z = origins[3 * i + 2];
        ray.tnear = 0.0f;
        ray.dir_x = directions[3 * i];
        ray.dir_y = directions[3 * i + 1];
        ray.dir_z = directions[3 * i + 2];
        ray.time = 0.0f;
        ray.tfar = lengths[i];
        ray.mask = 0xFFFFFFFFu;
        ray.id = 0;
        ray.flags = 0;
        rtcOccluded1(traced->scene, &ray, NULL);
        blocked[i] = ray.tfar < 0.0f ? 0 : -1;
    }
}

/* The rays baker_occluded casts in a packet: 16 on a CPU with AVX-512, 8 with AVX2 (where
 * Embree traces that many lanes at once), else 1 (every ray alone). */
int baker_packets(void)
{
    if (__builtin_cpu_supports("avx512f"))
        return 16;
    return __builtin_cpu_supports("avx2") ? 8 : 1;
}
