#!/usr/bin/env bash
# After a change of the C ABI (runtime/capi, its header regenerated with
# `ZOO_BLESS_HEADER=1 cargo test -p zoo-capi --test header`): regenerates the P/Invoke functions
# (Runtime/Native/ZooNative.Functions.cs) from runtime/capi/include/zoo.h, then compiles the
# package and runs the binding check, which lists what is left to do by hand (structs and enums in
# Runtime/Native/ZooTypes.cs, the safe wrappers). Needs Mono (apt-get install -y mono-complete).
set -euo pipefail
package="$(cd "$(dirname "$0")/.." && pwd)"
header="$package/../../runtime/capi/include/zoo.h"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
cd "$package"
mcs -langversion:7.2 -nologo -out:"$tmp/generate-bindings.exe" "Tools~/GenerateBindings.cs" "Tests~/Header.cs"
mono "$tmp/generate-bindings.exe" "$header" Runtime/Native/ZooNative.Functions.cs
mapfile -t runtime < <(find Runtime -name '*.cs' -not -path 'Runtime/Unity/*' | sort)
mcs -langversion:7.2 -unsafe -target:library -nologo -out:"$tmp/Zoo.Runtime.dll" "${runtime[@]}"
mcs -langversion:7.2 -unsafe -nologo -r:"$tmp/Zoo.Runtime.dll" -out:"$tmp/zoo-tests.exe" \
  "Tests~/Program.cs" "Tests~/Header.cs" "Tests~/BindingCheck.cs" "Tests~/Vectors.cs" "Tests~/ConsoleTests.cs"
MONO_PATH="$tmp" mono "$tmp/zoo-tests.exe" check-bindings "$header"
