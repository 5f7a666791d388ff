// The page's glue over the WebAssembly build of runtime/prt_runtime.h (docs/web.md): one class,
// Pack, that owns a prt_runtime handle and the wasm-heap buffers the page passes to it. Every
// runtime status other than PRT_RUNTIME_OK becomes an Error carrying prt_runtime_last_error().
//
// Memory: the module's heap grows (ALLOW_MEMORY_GROWTH), which detaches the old typed-array
// views, so every read of the heap goes through a fresh view (this.M.HEAPF32 after the call).
import createPrtRuntime from './prt_runtime.js';

let modulePromise = null;

/** The wasm module, instantiated once per page. */
export function loadRuntimeModule() {
  if (!modulePromise) {
    modulePromise = createPrtRuntime().then((M) => {
      // A browser tab's memory budget: refuse any section that claims more than 1 GiB decoded
      // before allocating it (prt_runtime_set_max_section_bytes; uint64 → two i32 halves).
      M._prt_runtime_set_max_section_bytes(1024 * 1024 * 1024, 0);
      return M;
    });
  }
  return modulePromise;
}

export const LightingMode = Object.freeze({NWA: 0, BI: 1, PBI: 2});

export class Pack {
  /**
   * Opens a pack from its bytes (prt_runtime_open_memory). Throws Error(last error) when the
   * pack is unreadable or corrupt.
   * @param {object} M the module from loadRuntimeModule()
   * @param {Uint8Array} bytes
   */
  constructor(M, bytes) {
    this.M = M;
    const ptr = M._malloc(Math.max(1, bytes.length));
    if (!ptr) throw new Error(`out of wasm memory for a ${bytes.length}-byte pack`);
    M.HEAPU8.set(bytes, ptr);
    this.rt = M._prt_runtime_open_memory(ptr, bytes.length);
    M._free(ptr);  // the runtime copied what it keeps
    if (!this.rt) throw new Error(this.lastError());
    this.samples = M._prt_runtime_sample_count(this.rt);
    this.isImage = M._prt_runtime_is_image(this.rt) !== 0;
    // A glossy pack: visibility, relit towards the eye by triple products (docs/runtime.md,
    // "Glossy packs"); its frames depend on the view, not on a term budget.
    this.isGlossy = M._prt_runtime_is_glossy(this.rt) !== 0;
    // A glossy vertex pack (docs/glossy-transport.md): m BRDF terms per vertex, relit like a
    // diffuse pack and combined for the eye, so an orbit step relights (the m-term sum).
    this.brdfTerms = M._prt_runtime_brdf_terms(this.rt);
    this.triangles = M._prt_runtime_triangle_count(this.rt);
    this.cubemapSize = M._prt_runtime_cubemap_size(this.rt);
    this.coefficients = M._prt_runtime_coefficient_count(this.rt);
    this.channels = M._prt_runtime_transport_channels(this.rt);
    this.outPtr = M._malloc(this.samples * 12);
    if (!this.outPtr) throw new Error('out of wasm memory for the radiance buffer');
    this.envPtr = 0;
  }

  lastError() {
    return this.M.UTF8ToString(this.M._prt_runtime_last_error());
  }

  check(status, what) {
    if (status !== 0) throw new Error(`${what}: ${this.lastError()} (status ${status})`);
  }

  /** Positions, 3 floats per sample, the pack's order (a copy). */
  positions() {
    const M = this.M;
    const ptr = M._malloc(this.samples * 12);
    try {
      this.check(M._prt_runtime_get_positions(this.rt, ptr, this.samples), 'positions');
      return M.HEAPF32.slice(ptr >> 2, (ptr >> 2) + 3 * this.samples);
    } finally {
      M._free(ptr);
    }
  }

  /** Triangles, 3 sample indices each (a copy). */
  triangleIndices() {
    const M = this.M;
    const ptr = M._malloc(Math.max(1, this.triangles * 12));
    try {
      this.check(M._prt_runtime_get_triangles(this.rt, ptr, this.triangles), 'triangles');
      return M.HEAPU32.slice(ptr >> 2, (ptr >> 2) + 3 * this.triangles);
    } finally {
      M._free(ptr);
    }
  }

  /** An image pack's pixels that see the environment: 1 byte per sample, 1 = background. */
  imageBackground() {
    const M = this.M;
    const ptr = M._malloc(Math.max(1, this.samples));
    try {
      this.check(M._prt_runtime_get_image_background(this.rt, ptr, this.samples), 'background');
      return M.HEAPU8.slice(ptr, ptr + this.samples);
    } finally {
      M._free(ptr);
    }
  }

  /**
   * How much of each pixel of an image pack is surface (docs/image-relighting.md,
   * "Supersampling"): 1 float per sample, 1 surface, 0 background, in between on the partly
   * covered pixels of a supersampled pack, which show (1 − coverage) of the environment.
   */
  imageCoverage() {
    const M = this.M;
    const ptr = M._malloc(Math.max(4, 4 * this.samples));
    try {
      this.check(M._prt_runtime_get_image_coverage(this.rt, ptr, this.samples), 'coverage');
      return M.HEAPF32.slice(ptr >> 2, (ptr >> 2) + this.samples);
    } finally {
      M._free(ptr);
    }
  }

  /** The baked camera: {eye, target, up, fov (degrees, vertical), width, height}. */
  camera() {
    const M = this.M;
    const ptr = M._malloc(64);
    try {
      const f = ptr >> 2;
      this.check(M._prt_runtime_get_camera(this.rt, ptr, ptr + 12, ptr + 24, ptr + 36, ptr + 40,
                                            ptr + 44), 'camera');
      const h = M.HEAPF32;
      const i = M.HEAP32;
      return {eye: [h[f], h[f + 1], h[f + 2]], target: [h[f + 3], h[f + 4], h[f + 5]],
              up: [h[f + 6], h[f + 7], h[f + 8]], fov: h[f + 9], width: i[f + 10],
              height: i[f + 11]};
    } finally {
      M._free(ptr);
    }
  }

  /** The environment: linear RGB lat-long floats, rows from the top, width = 2 × height. */
  setEnvironment(rgb, width, height) {
    const M = this.M;
    const ptr = M._malloc(rgb.length * 4);
    if (!ptr) throw new Error('out of wasm memory for the environment map');
    try {
      M.HEAPF32.set(rgb, ptr >> 2);
      this.check(M._prt_runtime_set_environment_latlong(this.rt, ptr, width, height),
                 'environment');
    } finally {
      M._free(ptr);  // the runtime keeps its own copy
    }
  }

  setRotationY(radians) {
    this.check(this.M._prt_runtime_set_rotation_y(this.rt, radians), 'rotation');
  }

  /** The eye a glossy pack is relit towards (any pack accepts it; only glossy ones use it). */
  setEye(eye) {
    const M = this.M;
    const ptr = M._malloc(12);
    try {
      M.HEAPF32.set(eye, ptr >> 2);
      this.check(M._prt_runtime_set_eye(this.rt, ptr), 'eye');
    } finally {
      M._free(ptr);
    }
  }

  setPreview(on) {
    this.check(this.M._prt_runtime_set_preview(this.rt, on ? 1 : 0), 'preview');
  }

  setLightingMode(mode) {
    this.check(this.M._prt_runtime_set_lighting_mode(this.rt, mode), 'lighting mode');
  }

  /**
   * One frame: terms = 0 exact, else that many wavelet terms (a PBI frame by default; a glossy
   * pack's frame is the same whatever the terms). Returns a view of the radiance (3 floats per
   * sample, the pack's order) valid until the next call.
   */
  relight(terms) {
    const M = this.M;
    this.check(M._prt_runtime_relight(this.rt, terms, this.outPtr, this.samples), 'relight');
    return M.HEAPF32.subarray(this.outPtr >> 2, (this.outPtr >> 2) + 3 * this.samples);
  }

  // A glossy vertex pack: the last relight's terms combined for the current eye (no relight).
  reshade() {
    const M = this.M;
    this.check(M._prt_runtime_reshade(this.rt, this.outPtr, this.samples), 'reshade');
    return M.HEAPF32.subarray(this.outPtr >> 2, (this.outPtr >> 2) + 3 * this.samples);
  }

  memoryBytes() {
    return this.M._prt_runtime_memory_bytes(this.rt);
  }

  close() {
    if (this.rt) this.M._prt_runtime_close(this.rt);
    if (this.outPtr) this.M._free(this.outPtr);
    this.rt = 0;
    this.outPtr = 0;
  }
}
