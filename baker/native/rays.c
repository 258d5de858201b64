/* Embree's ray queries for baker, called through ctypes (baker/rays/native.py).
 *
 * embreex casts each ray from a Cython loop that reads numpy buffers item by item and fills
 * eight result arrays, and copies a scene's vertices one by one through Python; this file
 * reads and writes plain float32/int32 rows and asks Embree the same questions (rtcIntersect1,
 * rtcOccluded1, default arguments) of the same library (the libembree4 that embreex's wheel
 * ships, loaded by native.py before this file): 1.04-1.10x embreex's rate on nearest hits, a
 * scene built 5x faster, and on an AVX-512 CPU occlusion in packets of 16 rays
 * (benchmarks/bench_rays.py). The library is not linked here: its symbols are resolved when
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

/* Sixteen rays, a row each (Embree's RTCRay16), for rtcOccluded16. */
struct __attribute__((aligned(64))) RTCRay16 {
    float org_x[16], org_y[16], org_z[16], tnear[16];
    float dir_x[16], dir_y[16], dir_z[16], time[16];
    float tfar[16];
    unsigned int mask[16], id[16], flags[16];
};

void rtcOccluded16(const int *valid, RTCScene scene, struct RTCRay16 *ray, void *args);

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
 * (-1 for a miss), u, v (n,) float32 its barycentric weights, as embreex's run(output=1). */
void baker_intersect(const Traced *traced, const float *origins, const float *directions,
                     float *lengths, long n, int *triangle, float *u, float *v)
{
    struct RTCRayHit rh;
    long i;
    for (i = 0; i < n; i++) {
        rh.ray.org_x = origins[3 * i];
        rh.ray.org_y = origins[3 * i + 1];
        rh.ray.org_z = origins[3 * i + 2];
        rh.ray.tnear = 0.0f;
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

/* Whether anything lies along each of n rays (as baker_intersect takes them; lengths kept):
 * blocked (n,) int32 0 where something does, -1 where nothing does, as embreex's OCCLUDED.
 *
 * On a CPU with AVX-512, whole runs of 16 consecutive rays go to Embree as one packet
 * (rtcOccluded16), the rest one by one: 1.3-1.5x the rate of single rays on a bake's
 * obscurance rays (benchmarks/bench_rays.py), where packets of 8, or of 16 with lanes left
 * empty, were slower than single rays. Each ray's answer is its own, whatever rays share its
 * packet: the same as rtcOccluded1's (tests/test_native_rays.py). */
void baker_occluded(const Traced *traced, const float *origins, const float *directions,
                    const float *lengths, long n, int *blocked)
{
    static const int __attribute__((aligned(64))) all[16] = {
        -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1, -1};
    struct RTCRay16 packet;
    struct RTCRay ray;
    long i = 0, j;
    if (baker_packets())
        for (; i + 16 <= n; i += 16) {
            for (j = 0; j < 16; j++) {
                packet.org_x[j] = origins[3 * (i + j)];
                packet.org_y[j] = origins[3 * (i + j) + 1];
                packet.org_z[j] = origins[3 * (i + j) + 2];
                packet.tnear[j] = 0.0f;
                packet.dir_x[j] = directions[3 * (i + j)];
                packet.dir_y[j] = directions[3 * (i + j) + 1];
                packet.dir_z[j] = directions[3 * (i + j) + 2];
                packet.time[j] = 0.0f;
                packet.tfar[j] = lengths[i + j];
                packet.mask[j] = 0xFFFFFFFFu;
                packet.id[j] = 0;
                packet.flags[j] = 0;
            }
            rtcOccluded16(all, traced->scene, &packet, NULL);
            for (j = 0; j < 16; j++)
                blocked[i + j] = packet.tfar[j] < 0.0f ? 0 : -1;
        }
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

/* 1 where baker_occluded casts packets of 16 (the CPU has AVX-512, where Embree traces them
 * sixteen lanes at once), 0 where it casts every ray alone. */
int baker_packets(void)
{
    return __builtin_cpu_supports("avx512f") ? 1 : 0;
}
