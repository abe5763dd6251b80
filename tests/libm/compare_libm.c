/* How often musl's libm (loaded from the given shared object) and the C library's differ, on
 * what the decoder used to take from libm before format 1.15: logf of every CSOG opacity level
 * (bits 1-16) and sinf/acosf/sin/log on a million arguments each. For
 * scripts/libm_independence.sh: shows that the libm it preloads is really another one. */
#include <dlfcn.h>
#include <math.h>
#include <stdio.h>

int main(int argc, char **argv) {
    if (argc != 2) return 2;
    void *h = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!h) return 2;
    float (*m_logf)(float) = (float (*)(float))dlsym(h, "logf");
    double (*m_log)(double) = (double (*)(double))dlsym(h, "log");
    double (*m_sin)(double) = (double (*)(double))dlsym(h, "sin");
    float (*m_sinf)(float) = (float (*)(float))dlsym(h, "sinf");
    float (*m_acosf)(float) = (float (*)(float))dlsym(h, "acosf");
    long levels = 0, d_logf = 0, d_log = 0, d_sin = 0, d_sinf = 0, d_acosf = 0;
    for (int b = 1; b <= 16; b++) {
        float l = (float)((1u << b) - 1), eps = 0.5f / l;
        for (unsigned q = 0; q <= (1u << b) - 1; q++, levels++) {
            float a = 0.0f + (float)q * ((1.0f - 0.0f) / l);
            if (a < eps) a = eps;
            if (a > 1.0f - eps) a = 1.0f - eps;
            float x = a / (1.0f - a);
            d_logf += logf(x) != m_logf(x);
            d_log += log((double)x) != m_log((double)x);
        }
    }
    for (int i = 0; i < 1000000; i++) {
        double x = i * 3.2e-6;
        float c = (float)(i * 2e-6 - 1.0);
        d_sin += sin(x) != m_sin(x);
        d_sinf += sinf((float)x) != m_sinf((float)x);
        d_acosf += acosf(c) != m_acosf(c);
    }
    printf("C library vs musl: logf differs on %ld of %ld opacity levels, log on %ld; "
           "sinf on %ld, acosf on %ld, sin on %ld of 1,000,000 arguments\n",
           d_logf, levels, d_log, d_sinf, d_acosf, d_sin);
    return 0;
}
