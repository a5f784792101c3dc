#!/usr/bin/env bash
# The tests whose results depend on the CPU's instruction set, once more on an emulated
# AVX2-only CPU: tract and onnxruntime pick their matrix kernels at run time (AVX-512, VNNI,
# AVX2 + FMA), and most game machines have AVX2 and no AVX-512. Each test binary runs under
# `qemu-x86_64 -cpu Haswell-v4` (AVX2, FMA, F16C; no AVX-512, no VNNI), so a machine with
# AVX-512 checks what an AVX2 one computes. About 5 minutes on 2 cores after scripts/test.sh.
#
# Only the tests that run tract and onnxruntime in their own process: a program a test starts
# (the `zoo` binary, the compiled C examples, Python, Mono) runs on the real CPU, so the tests
# that compare such a program with the test's own results are skipped here.
set -euo pipefail
cd "$(dirname "$0")/.."
CPU=Haswell-v4
if ! command -v qemu-x86_64 >/dev/null; then
  if command -v apt-get >/dev/null && [ "$(id -u)" = 0 ]; then
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq qemu-user >/dev/null
  else
    echo "qemu-x86_64 is missing: install it with \`sudo apt-get install qemu-user\`" >&2
    exit 1
  fi
fi
# The emulated CPU must really lack AVX-512 (a qemu without AVX2 support would fail here too).
cat > target/avx2-check.rs <<'RS'
fn main() {
    let has = |f: bool, n: &'static str| if f { n } else { "" };
    println!(
        "{} {} {} {}",
        has(std::arch::is_x86_feature_detected!("avx2"), "avx2"),
        has(std::arch::is_x86_feature_detected!("fma"), "fma"),
        has(std::arch::is_x86_feature_detected!("avx512f"), "avx512f"),
        has(std::arch::is_x86_feature_detected!("avx512vnni"), "avx512vnni")
    );
}
RS
rustc -O -o target/avx2-check target/avx2-check.rs
FEATURES=$(qemu-x86_64 -cpu "$CPU" target/avx2-check 2>/dev/null | xargs)
if [ "$FEATURES" != "avx2 fma" ]; then
  echo "qemu-x86_64 -cpu $CPU reports '$FEATURES', not 'avx2 fma': it cannot stand for an AVX2-only CPU" >&2
  exit 1
fi
echo "emulated CPU: $CPU ($FEATURES; no AVX-512, no VNNI)"
bash scripts/onnxruntime.sh >/dev/null
export CARGO_TARGET_X86_64_UNKNOWN_LINUX_GNU_RUNNER="qemu-x86_64 -cpu $CPU"
# qemu warns about host CPU features TCG does not emulate; the tests' own output is kept.
cargo test --workspace --no-fail-fast \
  --test parity --test parity_rtn --test parity_rmr --test parity_arnn --test parity_inbetween \
  --test parity_rnngmm --test portable --test runtime --test runtime_alloc --test capi --test capi_tasks \
  -- --skip c_example "$@" 2> >(grep -v "^qemu-x86_64: warning: TCG doesn't support" >&2)
