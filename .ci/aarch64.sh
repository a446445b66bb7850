#!/usr/bin/env bash
# Runs the core tests (kernels incl. the NEON variants vs their scalar twins,
# the streaming conv stacks on synthetic geometries) for aarch64 under
# qemu-user. Debian/Ubuntu; needs root for apt. Called by .ci/run.
#
#   bash .ci/aarch64.sh             # every core test but the two prefix sweeps
#   bash .ci/aarch64.sh FILTER...   # cargo test arguments as given (all tests)
#
# The two sweeps of core/tests/stream_conv.rs (streaming encoders/decoders
# vs the prefix stack after every push, quadratic in the pushes) take 24 s
# natively and ~300 s under qemu; they check the streaming bookkeeping, which
# is the same on every ISA, and run natively in `cargo test --workspace`.
# Their kernels run under qemu in the other stream_conv tests.
set -euo pipefail
cd "$(dirname "$0")/.."
if ! command -v aarch64-linux-gnu-gcc >/dev/null || ! command -v qemu-aarch64 >/dev/null; then
    SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
    $SUDO apt-get update -qq
    $SUDO apt-get install -y -qq gcc-aarch64-linux-gnu qemu-user
fi
rustup target add aarch64-unknown-linux-gnu
args=("$@")
if [ ${#args[@]} -eq 0 ]; then
    args=(--lib --test stream_conv --
          --skip streaming_encoders_equal_the_prefix_encoder
          --skip streaming_decoders_equal_the_prefix_decoder)
fi
CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_LINKER=aarch64-linux-gnu-gcc \
CARGO_TARGET_AARCH64_UNKNOWN_LINUX_GNU_RUNNER="qemu-aarch64 -L /usr/aarch64-linux-gnu" \
    cargo test --release -p duolando-core --target aarch64-unknown-linux-gnu "${args[@]}"
