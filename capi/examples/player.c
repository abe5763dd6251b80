/* A minimal C player of .dlgs streams through the dlgs C ABI (include/dlgs.h).
 *
 *   player FILE.dlgs [--memory] [T ...]
 *
 * Opens FILE (from the path, or with --memory from bytes read into memory), prints what the
 * stream holds, decodes the Gaussians at each time T (default: the first and last frame of
 * every GOP and one time between frames) and prints one FNV-1a 64 checksum per frame over
 * every attribute buffer, so the output can be compared with the Rust API's. Timings go to
 * stderr. Build: cc player.c -I../include -L<target>/release -ldlgs_capi -o player
 */
#define _POSIX_C_SOURCE 199309L
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "dlgs.h"

static uint64_t fnv1a(uint64_t h, const void *data, size_t len) {
    const unsigned char *p = data;
    for (size_t i = 0; i < len; i++) {
        h ^= p[i];
        h *= 1099511628211ull;
    }
    return h;
}

static int check(DlgsStatus s, const char *what) {
    if (s != DLGS_STATUS_OK) {
        fprintf(stderr, "%s: %s: %s\n", what, dlgs_status_name(s), dlgs_last_error());
        return 1;
    }
    return 0;
}

static unsigned char *read_all(const char *path, size_t *len) {
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    fseek(f, 0, SEEK_END);
    long n = ftell(f);
    fseek(f, 0, SEEK_SET);
    unsigned char *buf = malloc(n > 0 ? (size_t)n : 1);
    if (buf && fread(buf, 1, (size_t)n, f) != (size_t)n) {
        free(buf);
        buf = NULL;
    }
    fclose(f);
    *len = (size_t)n;
    return buf;
}

int main(int argc, char **argv) {
    if (argc < 2) {
        fprintf(stderr, "usage: %s FILE.dlgs [--memory] [T ...]\n", argv[0]);
        return 2;
    }
    int memory = 0, first_time = 2;
    if (argc > 2 && strcmp(argv[2], "--memory") == 0) {
        memory = 1;
        first_time = 3;
    }
    DlgsDecoder *dec = NULL;
    if (memory) {
        size_t len = 0;
        unsigned char *bytes = read_all(argv[1], &len);
        if (!bytes) {
            fprintf(stderr, "cannot read %s\n", argv[1]);
            return 1;
        }
        DlgsStatus s = dlgs_open_memory(bytes, len, &dec);
        free(bytes); /* the library keeps its own copy */
        if (check(s, "dlgs_open_memory")) return 1;
    } else if (check(dlgs_open_path(argv[1], &dec), "dlgs_open_path")) {
        return 1;
    }
    DlgsInfo info;
    if (check(dlgs_info(dec, &info), "dlgs_info")) return 1;
    printf("dlgs %s, format %u.%u: %u GOPs x %u frames, %u frames at %.3f fps, %u static + %u dynamic, SH %u, language %u\n",
           dlgs_version(), info.version_major, info.version_minor, info.gop_count, info.gop_length,
           info.frame_count, info.fps, info.n_static, info.n_dynamic, info.sh_degree, info.lang_width);

    size_t n = info.n_gaussians, sh = (size_t)info.sh_coeffs * 3, lw = info.lang_width;
    DlgsFrameBuffers b = {
        .positions = malloc(n * 3 * sizeof(float)),
        .log_scales = malloc(n * 3 * sizeof(float)),
        .rotations = malloc(n * 4 * sizeof(float)),
        .opacity = malloc(n * sizeof(float)),
        .sh = malloc(n * sh * sizeof(float)),
        .lang_opacity = lw ? malloc(n * sizeof(float)) : NULL,
        .lang = lw ? malloc(n * lw * sizeof(float)) : NULL,
        .capacity = n,
    };

    /* Times: from the command line, or two per GOP plus one between frames. */
    int count = argc - first_time;
    double *times;
    if (count > 0) {
        times = malloc((size_t)count * sizeof(double));
        for (int i = 0; i < count; i++) times[i] = atof(argv[first_time + i]);
    } else {
        count = (int)info.gop_count * 2 + 1;
        times = malloc((size_t)count * sizeof(double));
        for (uint32_t g = 0; g < info.gop_count; g++) {
            times[2 * g] = g * info.gop_length / info.fps;
            times[2 * g + 1] = ((g + 1) * info.gop_length - 1) / info.fps;
        }
        times[count - 1] = 1.2345 / info.fps;
    }

    const float eye[3] = {0.0f, 0.0f, 0.0f};
    int failed = 0;
    for (int i = 0; i < count; i++) {
        uint32_t written = 0;
        struct timespec a, z;
        clock_gettime(CLOCK_MONOTONIC, &a);
        DlgsStatus s = dlgs_decode_frame(dec, times[i], eye, &b, &written);
        clock_gettime(CLOCK_MONOTONIC, &z);
        if (check(s, "dlgs_decode_frame")) {
            failed = 1;
            continue;
        }
        uint64_t h = 1469598103934665603ull;
        h = fnv1a(h, b.positions, written * 3 * sizeof(float));
        h = fnv1a(h, b.log_scales, written * 3 * sizeof(float));
        h = fnv1a(h, b.rotations, written * 4 * sizeof(float));
        h = fnv1a(h, b.opacity, written * sizeof(float));
        h = fnv1a(h, b.sh, written * sh * sizeof(float));
        if (lw) {
            h = fnv1a(h, b.lang_opacity, written * sizeof(float));
            h = fnv1a(h, b.lang, written * lw * sizeof(float));
        }
        printf("t=%.6f n=%u fnv=%016llx\n", times[i], written, (unsigned long long)h);
        fprintf(stderr, "t=%.6f decoded in %.2f ms\n", times[i],
                (z.tv_sec - a.tv_sec) * 1e3 + (z.tv_nsec - a.tv_nsec) / 1e6);
    }

    /* Played in time order, the next GOP was decoded ahead on a background thread. */
    uint64_t hits = 0;
    if (!check(dlgs_read_ahead_hits(dec, &hits), "dlgs_read_ahead_hits")) {
        printf("GOPs ready from read-ahead: %llu\n", (unsigned long long)hits);
    }

    /* Errors are reported, not crashes: a time past the end. */
    uint32_t w;
    DlgsStatus s = dlgs_decode_frame(dec, info.duration + 1.0, eye, &b, &w);
    printf("past the end: %s\n", dlgs_status_name(s));

    dlgs_close(dec);
    free(times);
    free(b.positions);
    free(b.log_scales);
    free(b.rotations);
    free(b.opacity);
    free(b.sh);
    free(b.lang_opacity);
    free(b.lang);
    return failed;
}
