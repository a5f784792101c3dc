"""Per-frame root speed of generated BVH files against real clips: the 1-D Wasserstein distance
(W1, as `zoo bench synthesis` computes it) and the mean frame-to-frame change of the speed, with
the root displacements unsmoothed and smoothed by a centred Gaussian of 1-5 frames (what the
refiner's `--refiner-root-smoothing` would ask of it). The root is the first joint whose
position channels move. Needs numpy.

The measurement of 2026-11-26, commit 12bb67a (docs/rnn-gmm.md, "Root smoothing"), RNN-only
sequences from eight validation takes:

    D=../shared/data/bandai2; M=RUN_DIR_OF_THE_GENERATOR; k=0
    for c in run_active_001 run_normal_002 walk_elderly_001 walk_masculine_002 \
             walk-turn-left_normal_001 walk-turn-left_feminine_002 walk-turn-right_active_002 walk-turn-right_normal_001; do
      k=$((k+1)); zoo generate --model $M --from $D/dataset-2_$c.bvh.gz:29 --seconds 60 --count 4 --seed $k \
          --no-refiner --out gen/$c
    done
    python3 scripts/root_speed_smoothing.py "$D/dataset-2_*_[aefmn]*_00[12].bvh*" gen/*/seed*.bvh
"""
import gzip, sys, glob, math
import numpy as np

def load_root_xz(path):
    op = gzip.open if path.endswith('.gz') else open
    with op(path, 'rt') as f:
        lines = f.read().split('\n')
    chans = []  # per joint list of channel names, in order
    i = 0
    while not lines[i].strip().startswith('MOTION'):
        s = lines[i].split()
        if s and s[0] == 'CHANNELS':
            chans.append(s[2:])
        i += 1
    frames = int(lines[i+1].split()[1]); ft = float(lines[i+2].split()[2])
    data = np.array([[float(v) for v in l.split()] for l in lines[i+3:i+3+frames] if l.strip()])
    off = 0
    for c in chans:
        ix, iz = off + c.index('Xposition'), off + c.index('Zposition')
        xz = data[:, [ix, iz]]
        if np.ptp(xz) > 1e-3:
            return xz, 1.0 / ft
        off += len(c)
    return xz, 1.0 / ft

def speeds(xz, fps):
    d = np.diff(xz, axis=0)
    return np.hypot(d[:, 0], d[:, 1]) * fps

def gauss(xz, sigma):
    if sigma <= 0: return xz
    r = int(math.ceil(3 * sigma)); k = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma) ** 2)
    out = np.empty_like(xz)
    n = len(xz)
    for t in range(n):
        lo, hi = max(0, t - r), min(n, t + r + 1)
        w = k[lo - t + r:hi - t + r]
        out[t] = (w[:, None] * xz[lo:hi]).sum(0) / w.sum()
    return out

def gauss_vel(xz, sigma):
    """Smooth the per-frame displacement (what the refiner's root values are), then integrate."""
    d = np.diff(xz, axis=0)
    ds = gauss(d, sigma)
    return np.vstack([xz[:1], xz[:1] + np.cumsum(ds, axis=0)])

def w1(a, b):
    a = np.sort(a); b = np.sort(b)
    allv = np.sort(np.concatenate([a, b]))
    ca = np.searchsorted(a, allv[:-1], side='right') / len(a)
    cb = np.searchsorted(b, allv[:-1], side='right') / len(b)
    return float(np.sum(np.abs(ca - cb) * np.diff(allv)))

if len(sys.argv) < 3:
    sys.exit("usage: root_speed_smoothing.py 'REAL_GLOB' GENERATED.bvh ...")
ref = sys.argv[1]; gen = sys.argv[2:]
reals = [speeds(*load_root_xz(p)) for p in sorted(glob.glob(ref))]
real = np.concatenate(reals)
racc = np.concatenate([np.abs(np.diff(r)) for r in reals])
print(f"real: {len(real)} frames, mean {real.mean():.1f} std {real.std():.1f} p5 {np.percentile(real,5):.1f} p95 {np.percentile(real,95):.1f}  mean |dspeed| {racc.mean():.2f}")
clips = [load_root_xz(p) for p in gen]
for sigma in [0, 1, 1.5, 2, 3, 5]:
    ss = [speeds(gauss_vel(xz, sigma), fps) for xz, fps in clips]
    s = np.concatenate(ss)
    acc = np.concatenate([np.abs(np.diff(x)) for x in ss])
    print(f"gen sigma {sigma}: mean {s.mean():.1f} std {s.std():.1f} p5 {np.percentile(s,5):.1f} p95 {np.percentile(s,95):.1f}  W1 {w1(s, real):.2f}  mean |dspeed| {acc.mean():.2f}")
