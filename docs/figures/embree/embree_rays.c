/* Embree's side of the ray casting comparison (docs/figures/embree/run.sh); benchmark only, never part of photon.
 *
 * Usage: embree_rays DIR NAME THREADS
 * Reads DIR/NAME.mesh and DIR/NAME.{coherent,incoherent}.rays as written by photon's `raycast` example, builds an
 * Embree scene of one triangle geometry (default build quality, static scene) on a device of THREADS threads,
 * and times single-ray queries (rtcIntersect1, rtcOccluded1; tnear 0, tfar infinity), the rays split over
 * THREADS OpenMP threads in chunks of 256. Prints lines in the format of `raycast time`:
 *   embree NAME THREADS build SECONDS BYTES_PER_TRIANGLE
 *   embree NAME THREADS {closest,any} {coherent,incoherent} MRAYS_PER_S HITS
 * Rates are medians of 5 passes, the build time the median of 3 builds. Bytes per triangle are what the device
 * holds after the build (its memory monitor) plus the vertex and index buffers. */
#include <embree3/rtcore.h>
#include <math.h>
#include <omp.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

static ssize_t device_bytes = 0;

static bool monitor(void *user, ssize_t bytes, bool post) {
    (void)user;
    (void)post;
    __atomic_add_fetch(&device_bytes, bytes, __ATOMIC_SEQ_CST);
    return true;
}

static void *read_file(const char *path, size_t *len) {
    FILE *f = fopen(path, "rb");
    if (!f) {
        fprintf(stderr, "%s: cannot open\n", path);
        exit(2);
    }
    fseek(f, 0, SEEK_END);
    *len = (size_t)ftell(f);
    fseek(f, 0, SEEK_SET);
    void *buf = malloc(*len + 16);
    if (fread(buf, 1, *len, f) != *len) {
        fprintf(stderr, "%s: short read\n", path);
        exit(2);
    }
    fclose(f);
    return buf;
}

static double now(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
}

static int cmp(const void *a, const void *b) {
    double x = *(const double *)a, y = *(const double *)b;
    return (x > y) - (x < y);
}

static double median(double *v, int n) {
    qsort(v, n, sizeof(double), cmp);
    return v[n / 2];
}

static uint32_t nv, nf;
static float *vertices;
static uint32_t *indices;

static RTCScene build(RTCDevice dev) {
    RTCScene scene = rtcNewScene(dev);
    RTCGeometry geom = rtcNewGeometry(dev, RTC_GEOMETRY_TYPE_TRIANGLE);
    rtcSetSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, vertices, 0, 12, nv);
    rtcSetSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, indices, 0, 12, nf);
    rtcCommitGeometry(geom);
    rtcAttachGeometry(scene, geom);
    rtcReleaseGeometry(geom);
    rtcCommitScene(scene);
    return scene;
}

int main(int argc, char **argv) {
    if (argc != 4) {
        fprintf(stderr, "usage: embree_rays DIR NAME THREADS\n");
        return 2;
    }
    const char *dir = argv[1], *name = argv[2];
    int threads = atoi(argv[3]);
    char path[4096], config[64];
    size_t len;
    snprintf(path, sizeof path, "%s/%s.mesh", dir, name);
    uint32_t *mesh = read_file(path, &len);
    nv = mesh[0];
    nf = mesh[1];
    /* Embree reads vertex buffers with 16-byte loads: the buffer has 16 spare bytes from read_file's padding. */
    vertices = (float *)(mesh + 2);
    indices = mesh + 2 + 3 * nv;

    snprintf(config, sizeof config, "threads=%d", threads);
    RTCDevice dev = rtcNewDevice(config);
    rtcSetDeviceMemoryMonitorFunction(dev, monitor, NULL);
    double secs[5];
    RTCScene scene = NULL;
    for (int i = 0; i < 3; i++) {
        if (scene) rtcReleaseScene(scene);
        device_bytes = 0;
        double t0 = now();
        scene = build(dev);
        secs[i] = now() - t0;
    }
    double bytes = (double)device_bytes + 12.0 * nv + 12.0 * nf;
    printf("embree %s %d build %.4f %.1f\n", name, threads, median(secs, 3), bytes / nf);

    omp_set_num_threads(threads);
    const char *kinds[2] = {"coherent", "incoherent"};
    for (int k = 0; k < 2; k++) {
        snprintf(path, sizeof path, "%s/%s.%s.rays", dir, name, kinds[k]);
        uint32_t *raw = read_file(path, &len);
        long n = raw[0];
        const float *r = (const float *)(raw + 1);
        for (int q = 0; q < 2; q++) {
            long hits = 0;
            double rates[5];
            for (int pass = -1; pass < 5; pass++) {
                double t0 = now();
                long h = 0;
#pragma omp parallel for schedule(dynamic, 1) reduction(+ : h)
                for (long c = 0; c < n; c += 256) {
                    struct RTCIntersectContext ctx;
                    rtcInitIntersectContext(&ctx);
                    long end = c + 256 < n ? c + 256 : n;
                    for (long i = c; i < end; i++) {
                        const float *x = r + 6 * i;
                        struct RTCRayHit rh;
                        rh.ray.org_x = x[0];
                        rh.ray.org_y = x[1];
                        rh.ray.org_z = x[2];
                        rh.ray.dir_x = x[3];
                        rh.ray.dir_y = x[4];
                        rh.ray.dir_z = x[5];
                        rh.ray.tnear = 0.0f;
                        rh.ray.tfar = INFINITY;
                        rh.ray.mask = 0xFFFFFFFFu;
                        rh.ray.time = 0.0f;
                        rh.ray.flags = 0;
                        rh.ray.id = 0;
                        if (q == 0) {
                            rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
                            rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
                            rtcIntersect1(scene, &ctx, &rh);
                            h += rh.hit.geomID != RTC_INVALID_GEOMETRY_ID;
                        } else {
                            rtcOccluded1(scene, &ctx, &rh.ray);
                            h += rh.ray.tfar < 0.0f;
                        }
                    }
                }
                if (pass < 0) hits = h; /* a warm-up pass that counts the hits */
                else rates[pass] = n / (now() - t0) / 1e6;
            }
            printf("embree %s %d %s %s %.3f %ld\n", name, threads, q == 0 ? "closest" : "any", kinds[k],
                   median(rates, 5), hits);
        }
        free(raw);
    }
    rtcReleaseScene(scene);
    rtcReleaseDevice(dev);
    free(mesh);
    return 0;
}
