#!/usr/bin/env bash
# Fetch the viewer's JavaScript libraries from the npm registry (pinned) and copy them, each with its
# licence file, into src/loosefit/viz/static/vendor/. The result is committed, so that installing
# loosefit needs no npm; rerun this (`make viewer-vendor`) only to change a version.
#
# three 0.147.0 is the last release that ships both a classic-script build (build/three.min.js, global
# THREE) and classic OrbitControls (examples/js): classic scripts are what lets an exported page open
# from disk (file://), where Chromium refuses ES-module imports.
#
# onnxruntime-web runs the garment's step model in the live page (`loosefit view --live`, served only, so an ES
# module is fine there). Its WebGPU build (dist/ort.webgpu.min.mjs) also carries the WebAssembly CPU backend, so one
# runtime file pair serves both: ort-wasm-simd-threaded.asyncify.{mjs,wasm}. The package ships no licence file;
# package.json says MIT.
set -euo pipefail
THREE_VERSION=0.147.0
UPLOT_VERSION=1.6.32
ORT_WEB_VERSION=1.31.1
here="$(cd "$(dirname "$0")/.." && pwd)"
dest="$here/src/loosefit/viz/static/vendor"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
cd "$tmp"
npm pack --silent "three@$THREE_VERSION" "uplot@$UPLOT_VERSION" "onnxruntime-web@$ORT_WEB_VERSION" >/dev/null
mkdir three uplot ort
tar xzf "three-$THREE_VERSION.tgz" -C three
tar xzf "uplot-$UPLOT_VERSION.tgz" -C uplot
tar xzf "onnxruntime-web-$ORT_WEB_VERSION.tgz" -C ort
mkdir -p "$dest"
rm -f "$dest"/*
cp three/package/build/three.min.js "$dest/three.min.js"
cp three/package/examples/js/controls/OrbitControls.js "$dest/OrbitControls.js"
cp three/package/LICENSE "$dest/LICENSE.three"
cp uplot/package/dist/uPlot.iife.min.js "$dest/uPlot.iife.min.js"
cp uplot/package/dist/uPlot.min.css "$dest/uPlot.min.css"
cp uplot/package/LICENSE "$dest/LICENSE.uplot"
for f in ort.webgpu.min.mjs ort-wasm-simd-threaded.asyncify.mjs ort-wasm-simd-threaded.asyncify.wasm; do
  cp "ort/package/dist/$f" "$dest/$f"
done
{
  echo "three $THREE_VERSION (npm): three.min.js = build/three.min.js, OrbitControls.js = examples/js/controls/OrbitControls.js, LICENSE.three (MIT)"
  echo "uplot $UPLOT_VERSION (npm): uPlot.iife.min.js, uPlot.min.css = dist/, LICENSE.uplot (MIT)"
  echo "onnxruntime-web $ORT_WEB_VERSION (npm): ort.webgpu.min.mjs, ort-wasm-simd-threaded.asyncify.mjs, ort-wasm-simd-threaded.asyncify.wasm = dist/ (MIT, per its package.json; no licence file in the package)"
  echo "fetched by scripts/fetch_viewer_vendor.sh (make viewer-vendor)"
  (cd "$dest" && sha256sum three.min.js OrbitControls.js uPlot.iife.min.js uPlot.min.css ort.webgpu.min.mjs \
    ort-wasm-simd-threaded.asyncify.mjs ort-wasm-simd-threaded.asyncify.wasm)
} > "$dest/VERSIONS.txt"
echo "wrote $dest"
