/* The AO lens: batched range compression of radar / lidar pulses (see rtsar/lens_plan.py).
 *
 * In the optical processor of Psaltis & Wagner (1981) a lens Fourier-transforms the light
 * diffracted by the acousto-optic cell; here the lens is an FFT.  Per pulse (row):
 *
 *   x·pre -> DFT(SIGN1, NFFT) [-> ·spectrum -> DFT(SIGN2, NFFT)] -> bins -> ·post
 *
 * with DFT(sign)[k] = sum_n x[n] exp(sign·i2πkn/NFFT), unnormalised; x is zero-padded from S
 * to NFFT samples and bin b of the output is DFT index (BIN_OFFSET + b) mod NFFT.  Everything
 * happens in one launch and the line never returns to global memory between the passes.
 *
 * The transforms are Stockham autosort FFTs: radix-8 stages, then one radix-4 or radix-2 stage,
 * ping-ponging between two __local buffers.  Stage (p, R), with p the length of the
 * sub-transforms already done, computes for every butterfly j < NFFT/R (k = j mod p):
 *   a[r] = src[j + r·NFFT/R] · w^(r·k),  w = exp(sign·i2π/(pR)),  r < R
 *   dst[(j - k)·R + k + r·p] = (R-point DFT of a)[r]
 *
 * Two kernels, one per kind of device (the host picks one):
 *
 *   lens_lanes  (build with -DLANES=L)       CPUs.  One work-item per L pulses, work-groups of
 *               one item.  The line of L pulses is held "structure of arrays": element n is a
 *               pair of realL vectors (real parts, imaginary parts), so every butterfly works
 *               on L pulses at once with plain vector instructions and a twiddle factor is a
 *               broadcast scalar.  Rows are transposed in (and out) with 8×8 shuffles when
 *               L = 8.  Needs 16·L·NFFT bytes of local memory (32·L·NFFT in double).
 *   lens_group  (build with -DGROUP_SIZE=G)  GPUs.  One work-group of G items per pulse, the
 *               line in local memory as real2 (16·NFFT bytes, 32·NFFT in double), barriers
 *               between stages; with -DSCRATCH_GLOBAL=1 the two lines are the pulse's rows
 *               of a global scratch buffer instead, for devices whose local memory is smaller
 *               (NVIDIA's 48 KiB against radarsat1's 4096 points).
 *
 * Build options: NFFT and LOG2_NFFT (a power of two >= 2), S (<= NFFT), BIN_COUNT,
 * BIN_OFFSET (0 <= BIN_OFFSET < NFFT), SIGN1, TWO_PASS (0 or 1), SIGN2, LANES or GROUP_SIZE
 * (with SCRATCH_GLOBAL, 0 or 1), and DOUBLE (0 or 1): with DOUBLE=1 every sample, twiddle and
 * sum is a double (the device must support cl_khr_fp64) and the lines need twice the memory.
 *
 * Buffers hold complex values as real2, i.e. float2 or double2 (x = real part, y = imaginary
 * part): shots[pulses][S], lines[pulses][BIN_COUNT], pre[S], spectrum[NFFT] (read only if
 * TWO_PASS), post[BIN_COUNT] and twiddle[NFFT] = exp(-i2πm/NFFT), computed in float64 on the
 * host; sign +1 uses its conjugate.
 */

#if !defined(NFFT) || !defined(LOG2_NFFT) || !defined(S) || !defined(BIN_COUNT) || \
    !defined(BIN_OFFSET) || !defined(SIGN1)
#error "lens.cl needs -DNFFT -DLOG2_NFFT -DS -DBIN_COUNT -DBIN_OFFSET -DSIGN1"
#endif
#if (1 << LOG2_NFFT) != NFFT || NFFT < 2
#error "NFFT must be 2**LOG2_NFFT >= 2"
#endif
#if S > NFFT
#error "S must not exceed NFFT"
#endif
#ifndef TWO_PASS
#define TWO_PASS 0
#endif
#ifndef SCRATCH_GLOBAL
#define SCRATCH_GLOBAL 0
#endif
#ifndef SIGN2
#define SIGN2 (-(SIGN1))
#endif

/* Sample type: float (default) or double (-DDOUBLE=1, needs cl_khr_fp64; the host checks). */
#if defined(DOUBLE) && DOUBLE
#pragma OPENCL EXTENSION cl_khr_fp64 : enable
#define REAL double
#define SQRT1_2 M_SQRT1_2
#else
#define REAL float
#define SQRT1_2 M_SQRT1_2_F
#endif
#define CAT_(a, b) a##b
#define CAT(a, b) CAT_(a, b)
#define real REAL
#define real2 CAT(REAL, 2)
#define real8 CAT(REAL, 8)

/* radix-8 stages, then one radix-4 or radix-2 stage when LOG2_NFFT is not a multiple of 3 */
#define N_RADIX8 (LOG2_NFFT / 3)
#define N_STAGES (N_RADIX8 + (LOG2_NFFT % 3 != 0))
#define LAST_RADIX (1 << (LOG2_NFFT % 3))

#define BIN_INDEX(b) ((BIN_OFFSET + (b)) & (NFFT - 1))

/* exp(sign·i2πm/NFFT) from the table of exp(-i2πm/NFFT) */
inline real2 twiddle_at(__global const real2 *twiddle, const uint m, const int sign)
{
    const real2 w = twiddle[m];
    return sign > 0 ? (real2)(w.x, -w.y) : w;
}

/* Complex product (the real2 operator * is element-wise, not a complex product). */
inline real2 cmul(const real2 a, const real2 b)
{
    return (real2)(a.x * b.x - a.y * b.y, a.x * b.y + a.y * b.x);
}

/* ========================================================================================= */
/* lens_lanes: L pulses per work-item, vectors across pulses                                 */
/* ========================================================================================= */
#ifdef LANES

#if LANES == 1
#define realL REAL
#define vloadL(i, p) ((p)[i])
#define vstoreL(v, i, p) ((p)[i] = (v))
#else
#define realL CAT(REAL, LANES)
#define vloadL CAT(vload, LANES)
#define vstoreL CAT(vstore, LANES)
#endif

/* L complex numbers, one per pulse: real parts and imaginary parts */
typedef struct {
    realL re;
    realL im;
} cvec;

inline cvec cv_make(const realL re, const realL im)
{
    cvec c;
    c.re = re;
    c.im = im;
    return c;
}

inline cvec cv_add(const cvec a, const cvec b) { return cv_make(a.re + b.re, a.im + b.im); }

inline cvec cv_sub(const cvec a, const cvec b) { return cv_make(a.re - b.re, a.im - b.im); }

/* a · w for a scalar complex w (the same for every pulse) */
inline cvec cv_scale(const cvec a, const real2 w)
{
    return cv_make(a.re * w.x - a.im * w.y, a.re * w.y + a.im * w.x);
}

/* a · (sign·i) */
inline cvec cv_mul_si(const cvec a, const int sign)
{
    return sign > 0 ? cv_make(-a.im, a.re) : cv_make(a.im, -a.re);
}

/* a · exp(sign·iπ/4) */
inline cvec cv_mul_w8(const cvec a, const int sign)
{
    return sign > 0 ? cv_make((a.re - a.im) * SQRT1_2, (a.re + a.im) * SQRT1_2)
                    : cv_make((a.re + a.im) * SQRT1_2, (a.im - a.re) * SQRT1_2);
}

/* a · exp(sign·i3π/4) */
inline cvec cv_mul_w83(const cvec a, const int sign)
{
    return sign > 0 ? cv_make(-(a.re + a.im) * SQRT1_2, (a.re - a.im) * SQRT1_2)
                    : cv_make((a.im - a.re) * SQRT1_2, -(a.re + a.im) * SQRT1_2);
}

inline void cv_dft2(cvec *a)
{
    const cvec t = cv_sub(a[0], a[1]);
    a[0] = cv_add(a[0], a[1]);
    a[1] = t;
}

inline void cv_dft4(cvec *a, const int sign)
{
    const cvec t0 = cv_add(a[0], a[2]), t1 = cv_sub(a[0], a[2]);
    const cvec t2 = cv_add(a[1], a[3]), t3 = cv_mul_si(cv_sub(a[1], a[3]), sign);
    a[0] = cv_add(t0, t2);
    a[2] = cv_sub(t0, t2);
    a[1] = cv_add(t1, t3);
    a[3] = cv_sub(t1, t3);
}

inline void cv_dft8(cvec *a, const int sign)
{
    cvec e[4] = {a[0], a[2], a[4], a[6]};
    cvec o[4] = {a[1], a[3], a[5], a[7]};
    cv_dft4(e, sign);
    cv_dft4(o, sign);
    o[1] = cv_mul_w8(o[1], sign);
    o[2] = cv_mul_si(o[2], sign);
    o[3] = cv_mul_w83(o[3], sign);
    for (int k = 0; k < 4; ++k) {
        a[k] = cv_add(e[k], o[k]);
        a[k + 4] = cv_sub(e[k], o[k]);
    }
}

/* One Stockham stage (see the top of the file); `mul`, when not null, multiplies the inputs
 * first (the spectrum, fused into the first stage of the second pass). */
inline void cv_stage(__local const realL *restrict src_re, __local const realL *restrict src_im,
                     __local realL *restrict dst_re, __local realL *restrict dst_im,
                     const uint p, const uint R, const int sign,
                     __global const real2 *twiddle, __global const real2 *mul)
{
    const uint nb = NFFT / R;
    for (uint j = 0; j < nb; ++j) {
        cvec a[8];
        const uint k = j & (p - 1);
        const uint step = k * (NFFT / (p * R));
        for (uint r = 0; r < R; ++r) {
            const uint n = j + r * nb;
            cvec v = cv_make(src_re[n], src_im[n]);
            if (mul)
                v = cv_scale(v, mul[n]);
            if (p > 1 && r > 0)
                v = cv_scale(v, twiddle_at(twiddle, r * step, sign));
            a[r] = v;
        }
        if (R == 8)
            cv_dft8(a, sign);
        else if (R == 4)
            cv_dft4(a, sign);
        else
            cv_dft2(a);
        const uint base = (j - k) * R + k;
        for (uint r = 0; r < R; ++r) {
            dst_re[base + r * p] = a[r].re;
            dst_im[base + r * p] = a[r].im;
        }
    }
}

/* FFT of buffer `from` (0 or 1); the result lands in buffer from ^ (N_STAGES & 1). */
inline void cv_fft(__local realL (*re)[NFFT], __local realL (*im)[NFFT], const int from,
                   const int sign, __global const real2 *twiddle, __global const real2 *mul)
{
    int s = from;
    uint p = 1;
    for (int stage = 0; stage < N_RADIX8; ++stage) {
        cv_stage(re[s], im[s], re[s ^ 1], im[s ^ 1], p, 8, sign, twiddle, stage == 0 ? mul : 0);
        s ^= 1;
        p *= 8;
    }
#if LAST_RADIX > 1
    cv_stage(re[s], im[s], re[s ^ 1], im[s ^ 1], p, LAST_RADIX, sign, twiddle,
             N_RADIX8 == 0 ? mul : 0);
#endif
}

#if LANES == 8
/* 8×8 transpose of reals, c[k].s[l] = r[l].s[k], in three levels of two-vector shuffles
 * (written as swizzles: PoCL lowers them to unpck/shufps/vperm2f128 on x86). */
#define UNPACK_LO(a, b) (real8)((a).s0, (b).s0, (a).s1, (b).s1, (a).s4, (b).s4, (a).s5, (b).s5)
#define UNPACK_HI(a, b) (real8)((a).s2, (b).s2, (a).s3, (b).s3, (a).s6, (b).s6, (a).s7, (b).s7)
#define PAIRS_LO(a, b) (real8)((a).s0, (a).s1, (b).s0, (b).s1, (a).s4, (a).s5, (b).s4, (b).s5)
#define PAIRS_HI(a, b) (real8)((a).s2, (a).s3, (b).s2, (b).s3, (a).s6, (a).s7, (b).s6, (b).s7)
#define HALVES_LO(a, b) (real8)((a).s0123, (b).s0123)
#define HALVES_HI(a, b) (real8)((a).s4567, (b).s4567)

inline void transpose8(const real8 *r, real8 *c)
{
    real8 t[8], u[8];
    for (int i = 0; i < 4; ++i) {
        t[2 * i] = UNPACK_LO(r[2 * i], r[2 * i + 1]);
        t[2 * i + 1] = UNPACK_HI(r[2 * i], r[2 * i + 1]);
    }
    for (int h = 0; h < 8; h += 4) {
        u[h + 0] = PAIRS_LO(t[h + 0], t[h + 2]);
        u[h + 1] = PAIRS_HI(t[h + 0], t[h + 2]);
        u[h + 2] = PAIRS_LO(t[h + 1], t[h + 3]);
        u[h + 3] = PAIRS_HI(t[h + 1], t[h + 3]);
    }
    for (int i = 0; i < 4; ++i) {
        c[i] = HALVES_LO(u[i], u[i + 4]);
        c[i + 4] = HALVES_HI(u[i], u[i + 4]);
    }
}
#endif

__kernel __attribute__((reqd_work_group_size(1, 1, 1)))
void lens_lanes(__global const real2 *restrict shots,    /* [pulses][S] */
                __global real2 *restrict lines,          /* [pulses][BIN_COUNT] */
                __global const real2 *restrict pre,      /* [S] */
                __global const real2 *restrict spectrum, /* [NFFT], read if TWO_PASS */
                __global const real2 *restrict post,     /* [BIN_COUNT] */
                __global const real2 *restrict twiddle,  /* [NFFT] */
                const uint pulses)
{
    __local realL re[2][NFFT], im[2][NFFT];
    const uint first = get_group_id(0) * LANES;
    if (first >= pulses)
        return;
    const uint live = min((uint)LANES, pulses - first);

    /* rows of this work-item; missing pulses of a short last group repeat the last row */
    __global const real *row[LANES];
    __global real *out[LANES];
    for (uint l = 0; l < LANES; ++l) {
        const size_t pulse = min(first + l, pulses - 1);
        row[l] = (__global const real *)(shots + pulse * S);
        out[l] = (__global real *)(lines + pulse * BIN_COUNT);
    }

    /* ---- x·pre, transposed to one vector per sample, zero padding ----------------------- */
    uint n0 = 0;
#if LANES == 8
    for (; n0 + 4 <= S; n0 += 4) {
        real8 r[8], c[8];
        for (int l = 0; l < 8; ++l)
            r[l] = vload8(0, row[l] + 2 * n0);
        transpose8(r, c);
        for (int q = 0; q < 4; ++q) {
            const cvec v = cv_scale(cv_make(c[2 * q], c[2 * q + 1]), pre[n0 + q]);
            re[0][n0 + q] = v.re;
            im[0][n0 + q] = v.im;
        }
    }
#endif
    for (uint n = n0; n < S; ++n) {
        real xr[LANES], xi[LANES];
        for (uint l = 0; l < LANES; ++l) {
            xr[l] = row[l][2 * n];
            xi[l] = row[l][2 * n + 1];
        }
        const cvec v = cv_scale(cv_make(vloadL(0, xr), vloadL(0, xi)), pre[n]);
        re[0][n] = v.re;
        im[0][n] = v.im;
    }
    for (uint n = S; n < NFFT; ++n) {
        re[0][n] = (realL)(0);
        im[0][n] = (realL)(0);
    }

    /* ---- the transforms ---------------------------------------------------------------- */
    cv_fft(re, im, 0, SIGN1, twiddle, 0);
    int s = N_STAGES & 1;
#if TWO_PASS
    cv_fft(re, im, s, SIGN2, twiddle, spectrum);
    s ^= N_STAGES & 1;
#endif

    /* ---- bins · post, transposed back to rows ------------------------------------------ */
    uint b0 = 0;
#if LANES == 8
    for (; b0 + 4 <= BIN_COUNT; b0 += 4) {
        real8 c[8], r[8];
        for (int q = 0; q < 4; ++q) {
            const uint k = BIN_INDEX(b0 + q);
            const cvec v = cv_scale(cv_make(re[s][k], im[s][k]), post[b0 + q]);
            c[2 * q] = v.re;
            c[2 * q + 1] = v.im;
        }
        transpose8(c, r);
        if (live == 8) {
            for (int l = 0; l < 8; ++l)
                vstore8(r[l], 0, out[l] + 2 * b0);
        } else {
            for (uint l = 0; l < live; ++l)
                vstore8(r[l], 0, out[l] + 2 * b0);
        }
    }
#endif
    for (uint b = b0; b < BIN_COUNT; ++b) {
        const uint k = BIN_INDEX(b);
        const cvec v = cv_scale(cv_make(re[s][k], im[s][k]), post[b]);
        real yr[LANES], yi[LANES];
        vstoreL(v.re, 0, yr);
        vstoreL(v.im, 0, yi);
        for (uint l = 0; l < live; ++l) {
            out[l][2 * b] = yr[l];
            out[l][2 * b + 1] = yi[l];
        }
    }
}

#endif /* LANES */

/* ========================================================================================= */
/* lens_group: one work-group per pulse                                                      */
/* ========================================================================================= */
#ifdef GROUP_SIZE

/* a · (sign·i) */
inline real2 mul_si(const real2 a, const int sign)
{
    return sign > 0 ? (real2)(-a.y, a.x) : (real2)(a.y, -a.x);
}

/* a · exp(sign·iπ/4) */
inline real2 mul_w8(const real2 a, const int sign)
{
    return sign > 0 ? (real2)(a.x - a.y, a.x + a.y) * SQRT1_2
                    : (real2)(a.x + a.y, a.y - a.x) * SQRT1_2;
}

/* a · exp(sign·i3π/4) */
inline real2 mul_w83(const real2 a, const int sign)
{
    return sign > 0 ? (real2)(-a.x - a.y, a.x - a.y) * SQRT1_2
                    : (real2)(a.y - a.x, -a.x - a.y) * SQRT1_2;
}

inline void dft2(real2 *a)
{
    const real2 t = a[0] - a[1];
    a[0] = a[0] + a[1];
    a[1] = t;
}

inline void dft4(real2 *a, const int sign)
{
    const real2 t0 = a[0] + a[2], t1 = a[0] - a[2];
    const real2 t2 = a[1] + a[3], t3 = mul_si(a[1] - a[3], sign);
    a[0] = t0 + t2;
    a[2] = t0 - t2;
    a[1] = t1 + t3;
    a[3] = t1 - t3;
}

inline void dft8(real2 *a, const int sign)
{
    real2 e[4] = {a[0], a[2], a[4], a[6]};
    real2 o[4] = {a[1], a[3], a[5], a[7]};
    dft4(e, sign);
    dft4(o, sign);
    o[1] = mul_w8(o[1], sign);
    o[2] = mul_si(o[2], sign);
    o[3] = mul_w83(o[3], sign);
    for (int k = 0; k < 4; ++k) {
        a[k] = e[k] + o[k];
        a[k + 4] = e[k] - o[k];
    }
}

/* Where the group's two lines live: local memory, or the pulse's rows of a global scratch
 * buffer (SCRATCH_GLOBAL=1); either way a barrier orders the group's accesses to them. */
#if SCRATCH_GLOBAL
#define BUF __global
#define BUF_FENCE CLK_GLOBAL_MEM_FENCE
#else
#define BUF __local
#define BUF_FENCE CLK_LOCAL_MEM_FENCE
#endif

/* One Stockham stage shared by the GROUP_SIZE work-items of the group. */
inline void stage(BUF const real2 *restrict src, BUF real2 *restrict dst,
                  const uint lid, const uint p, const uint R, const int sign,
                  __global const real2 *twiddle, __global const real2 *mul)
{
    const uint nb = NFFT / R;
    for (uint j = lid; j < nb; j += GROUP_SIZE) {
        real2 a[8];
        const uint k = j & (p - 1);
        const uint step = k * (NFFT / (p * R));
        for (uint r = 0; r < R; ++r) {
            real2 v = src[j + r * nb];
            if (mul)
                v = cmul(v, mul[j + r * nb]);
            if (p > 1 && r > 0)
                v = cmul(v, twiddle_at(twiddle, r * step, sign));
            a[r] = v;
        }
        if (R == 8)
            dft8(a, sign);
        else if (R == 4)
            dft4(a, sign);
        else
            dft2(a);
        const uint base = (j - k) * R + k;
        for (uint r = 0; r < R; ++r)
            dst[base + r * p] = a[r];
    }
}

/* FFT of buf[from]; the result lands in buf[from ^ (N_STAGES & 1)]. */
inline void fft(BUF real2 (*buf)[NFFT], const int from, const uint lid, const int sign,
                __global const real2 *twiddle, __global const real2 *mul)
{
    int s = from;
    uint p = 1;
    for (int st = 0; st < N_RADIX8; ++st) {
        stage(buf[s], buf[s ^ 1], lid, p, 8, sign, twiddle, st == 0 ? mul : 0);
        barrier(BUF_FENCE);
        s ^= 1;
        p *= 8;
    }
#if LAST_RADIX > 1
    stage(buf[s], buf[s ^ 1], lid, p, LAST_RADIX, sign, twiddle, N_RADIX8 == 0 ? mul : 0);
    barrier(BUF_FENCE);
#endif
}

__kernel __attribute__((reqd_work_group_size(GROUP_SIZE, 1, 1)))
void lens_group(__global const real2 *restrict shots,    /* [pulses][S] */
                __global real2 *restrict lines,          /* [pulses][BIN_COUNT] */
                __global const real2 *restrict pre,      /* [S] */
                __global const real2 *restrict spectrum, /* [NFFT], read if TWO_PASS */
                __global const real2 *restrict post,     /* [BIN_COUNT] */
                __global const real2 *restrict twiddle,  /* [NFFT] */
                const uint pulses,
                __global real2 (*scratch)[NFFT])         /* [pulses][2], if SCRATCH_GLOBAL */
{
#if SCRATCH_GLOBAL
    __global real2 (*buf)[NFFT] = scratch + (size_t)get_group_id(0) * 2;
#else
    __local real2 buf[2][NFFT];
#endif
    const uint lid = get_local_id(0);
    const uint pulse = get_group_id(0);
    if (pulse >= pulses) /* uniform over the group */
        return;
    __global const real2 *x = shots + (size_t)pulse * S;

    for (uint n = lid; n < NFFT; n += GROUP_SIZE)
        buf[0][n] = n < S ? cmul(x[n], pre[n]) : (real2)(0, 0);
    barrier(BUF_FENCE);

    fft(buf, 0, lid, SIGN1, twiddle, 0);
    int s = N_STAGES & 1;
#if TWO_PASS
    fft(buf, s, lid, SIGN2, twiddle, spectrum);
    s ^= N_STAGES & 1;
#endif

    __global real2 *y = lines + (size_t)pulse * BIN_COUNT;
    for (uint b = lid; b < BIN_COUNT; b += GROUP_SIZE)
        y[b] = cmul(buf[s][BIN_INDEX(b)], post[b]);
}

#endif /* GROUP_SIZE */
