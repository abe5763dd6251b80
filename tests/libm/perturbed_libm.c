/* A libm whose transcendental functions are all off by a relative 1e-6, for
 * scripts/libm_independence.sh: preloaded into the decoder's conformance test, it must change
 * nothing (the decoder uses format-spec Appendix B, not the C library), while a control test
 * that does call the C library sees the difference. Only for that check; never linked. */
#define _GNU_SOURCE
#include <dlfcn.h>

#define WRAP1(name, T)                                                    \
    T name(T x) {                                                         \
        static T (*real)(T);                                              \
        if (!real) real = (T(*)(T))dlsym(RTLD_NEXT, #name);               \
        return real(x) * (T)(1.0 + 1e-6);                                 \
    }
#define WRAP2(name, T)                                                    \
    T name(T x, T y) {                                                    \
        static T (*real)(T, T);                                           \
        if (!real) real = (T(*)(T, T))dlsym(RTLD_NEXT, #name);            \
        return real(x, y) * (T)(1.0 + 1e-6);                              \
    }

WRAP1(log, double) WRAP1(logf, float) WRAP1(log2, double) WRAP1(log2f, float)
WRAP1(exp, double) WRAP1(expf, float) WRAP1(exp2, double) WRAP1(exp2f, float)
WRAP1(sin, double) WRAP1(sinf, float) WRAP1(cos, double) WRAP1(cosf, float)
WRAP1(acos, double) WRAP1(acosf, float) WRAP1(tanh, double) WRAP1(tanhf, float)
WRAP2(pow, double) WRAP2(powf, float)
