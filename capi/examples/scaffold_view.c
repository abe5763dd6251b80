/* Decode the Gaussians one camera sees in a .dlgs stream (either variant) through the dlgs C
 * ABI: a Scaffold-GS file (variant 1) generates them per camera, so dlgs_decode_frame refuses
 * it and dlgs_decode_frame_view is the call.
 *
 *   scaffold_view FILE.dlgs CX CY CZ [--cull] [T ...]
 *
 * The camera sits at (CX, CY, CZ) looking along +z (identity world-to-camera rotation),
 * 100x100 pixels, fx = fy = 100, principal point at the centre; --cull decodes only the anchors
 * whose Gaussians can reach into that image. Prints what dlgs_decode_frame says, then one line
 * per time T: the count and an FNV-1a 64 checksum over every attribute buffer.
 * Build: cc scaffold_view.c -I../include -L<target>/release -ldlgs_capi -o scaffold_view
 */
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "dlgs.h"

static uint64_t fnv1a(uint64_t h, const void *data, size_t len) {
    const unsigned char *p = data;
    for (size_t i = 0; i < len; i++) {
        h ^= p[i];
        h *= 1099511628211ull;
    }
    return h;
}

int main(int argc, char **argv) {
    if (argc < 5) {
        fprintf(stderr, "usage: %s FILE.dlgs CX CY CZ [--cull] [T ...]\n", argv[0]);
        return 2;
    }
    DlgsDecoder *d = NULL;
    DlgsStatus s = dlgs_open_path(argv[1], &d);
    if (s != DLGS_STATUS_OK) {
        fprintf(stderr, "open: %s: %s\n", dlgs_status_name(s), dlgs_last_error());
        return 1;
    }
    DlgsInfo info;
    dlgs_info(d, &info);
    printf("variant %u, %u + %u anchors or Gaussians, at most %u Gaussians a frame, "
           "language %u\n",
           info.variant, info.n_static, info.n_dynamic, info.n_gaussians, info.lang_width);

    DlgsView view;
    memset(&view, 0, sizeof view);
    for (int a = 0; a < 3; a++) view.camera_center[a] = strtof(argv[2 + a], NULL);
    view.world_to_camera[0] = view.world_to_camera[4] = view.world_to_camera[8] = 1.0f;
    view.fx = view.fy = 100.0f;
    view.cx = view.cy = 50.0f;
    view.width = view.height = 100;
    int first_time = 5;
    if (argc > 5 && strcmp(argv[5], "--cull") == 0) {
        view.cull = 1;
        first_time = 6;
    }

    size_t n = info.n_gaussians, k = info.sh_coeffs, lw = info.lang_width;
    size_t cap = n > 0 ? n : 1;
    float *pos = malloc(cap * 3 * sizeof(float)), *scale = malloc(cap * 3 * sizeof(float));
    float *rot = malloc(cap * 4 * sizeof(float)), *op = malloc(cap * sizeof(float));
    float *sh = malloc(cap * k * 3 * sizeof(float)), *lop = malloc(cap * sizeof(float));
    float *lang = malloc(cap * (lw > 0 ? lw : 1) * sizeof(float));
    DlgsFrameBuffers b = {pos, scale, rot, op, sh, lw ? lop : NULL, lw ? lang : NULL, cap};

    uint32_t written = 0;
    s = dlgs_decode_frame(d, 0.0, view.camera_center, &b, &written);
    printf("dlgs_decode_frame: %s\n", dlgs_status_name(s));

    for (int i = first_time; i < argc; i++) {
        double t = strtod(argv[i], NULL);
        DlgsFrameBuffers one = b;
        one.capacity = 1;
        s = dlgs_decode_frame_view(d, t, &view, &one, &written);
        if (s == DLGS_STATUS_BUFFER_TOO_SMALL) printf("one-Gaussian buffers: need %u\n", written);
        s = dlgs_decode_frame_view(d, t, &view, &b, &written);
        if (s != DLGS_STATUS_OK) {
            fprintf(stderr, "t=%s: %s: %s\n", argv[i], dlgs_status_name(s), dlgs_last_error());
            return 1;
        }
        size_t m = written;
        uint64_t h = 1469598103934665603ull;
        h = fnv1a(h, pos, m * 3 * sizeof(float));
        h = fnv1a(h, scale, m * 3 * sizeof(float));
        h = fnv1a(h, rot, m * 4 * sizeof(float));
        h = fnv1a(h, op, m * sizeof(float));
        h = fnv1a(h, sh, m * k * 3 * sizeof(float));
        if (lw) {
            h = fnv1a(h, lop, m * sizeof(float));
            h = fnv1a(h, lang, m * lw * sizeof(float));
        }
        printf("t=%.6f n=%zu fnv=%016llx\n", t, m, (unsigned long long)h);
    }
    free(pos); free(scale); free(rot); free(op); free(sh); free(lop); free(lang);
    dlgs_close(d);
    return 0;
}
