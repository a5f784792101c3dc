#!/usr/bin/env bash
# Builds the native library of the Unity package (zoo_capi, runtime/capi) for Linux x86_64 in the
# workspace's target folder and copies it to Runtime/Plugins/Linux/x86_64/, with the .meta that
# tells Unity which platform loads it. Run from anywhere in the checkout:
#
#   runtime/unity/Tools~/build-native.sh            # the workspace's dev profile (target/debug)
#   runtime/unity/Tools~/build-native.sh --release  # an optimised library to ship (target/release)
#
# Windows (x86_64, MSVC; in a Developer PowerShell, from the checkout):
#   cargo build -p zoo-capi --release
#   copy target\release\zoo_capi.dll engines\unity\Runtime\Plugins\Windows\x86_64\
# macOS (a universal library for Apple silicon and Intel):
#   rustup target add aarch64-apple-darwin x86_64-apple-darwin
#   cargo build -p zoo-capi --release --target aarch64-apple-darwin
#   cargo build -p zoo-capi --release --target x86_64-apple-darwin
#   mkdir -p runtime/unity/Runtime/Plugins/macOS
#   lipo -create -output runtime/unity/Runtime/Plugins/macOS/libzoo_capi.dylib \
#     target/aarch64-apple-darwin/release/libzoo_capi.dylib target/x86_64-apple-darwin/release/libzoo_capi.dylib
# Then select the library in Unity and tick its platform in the Inspector (Plugin Import Settings),
# or copy the .meta this script writes and change its platform section.
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
package="$(dirname "$here")"
root="$(cd "$package/../.." && pwd)"
profile=debug
args=()
if [[ "${1:-}" == "--release" ]]; then
  profile=release
  args=(--release)
elif [[ $# -gt 0 ]]; then
  echo "usage: $0 [--release]" >&2
  exit 2
fi
cd "$root"
cargo build -p zoo-capi "${args[@]}"
target="$(cargo metadata --format-version 1 --no-deps | python3 -c 'import json,sys; print(json.load(sys.stdin)["target_directory"])')"
lib="$target/$profile/libzoo_capi.so"
out="$package/Runtime/Plugins/Linux/x86_64"
mkdir -p "$out"
cp "$lib" "$out/libzoo_capi.so"
# Folder .meta files (stable GUIDs), so that Unity imports the folders of this package as its own.
for dir in Runtime/Plugins Runtime/Plugins/Linux Runtime/Plugins/Linux/x86_64; do
  cat > "$package/$dir.meta" <<META
fileFormatVersion: 2
guid: $(printf 'zoo %s' "$dir" | md5sum | cut -c1-32)
folderAsset: yes
DefaultImporter:
  externalObjects: {}
  userData:
  assetBundleName:
  assetBundleVariant:
META
done
# Unity's import settings: the library loads in the Linux editor and Linux x86_64 players only.
guid="$(printf 'zoo_capi linux x86_64' | md5sum | cut -c1-32)"
cat > "$out/libzoo_capi.so.meta" <<META
fileFormatVersion: 2
guid: $guid
PluginImporter:
  externalObjects: {}
  serializedVersion: 2
  iconMap: {}
  executionOrder: {}
  defineConstraints: []
  isPreloaded: 0
  isOverridable: 1
  isExplicitlyReferenced: 0
  validateReferences: 1
  platformData:
  - first:
      Any:
    second:
      enabled: 0
      settings: {}
  - first:
      Editor: Editor
    second:
      enabled: 1
      settings:
        CPU: x86_64
        DefaultValueInitialized: true
        OS: Linux
  - first:
      Standalone: Linux64
    second:
      enabled: 1
      settings:
        CPU: x86_64
  userData:
  assetBundleName:
  assetBundleVariant:
META
echo "zoo_capi ($profile): $out/libzoo_capi.so ($(du -h "$out/libzoo_capi.so" | cut -f1))"
