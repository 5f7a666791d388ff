// The page's drawing (docs/web.md): a vertex pack's mesh with three.js (WebGL2), coloured per
// vertex with the runtime's radiance, over the environment map as background; an image pack's
// pixels on a 2D canvas. The tonemap is prt-view's (vocabulary/image_io.cpp ToSrgb8 with
// ToneMap::kClamp): linear radiance × exposure, clamped to [0, 1], sRGB-encoded, per pixel after
// perspective-correct interpolation, as prt-view's rasterizer interpolates radiance.
import * as THREE from '../three/three.module.js';

// GLSL of vocabulary/image_io.cpp SrgbEncode.
const kSrgbGlsl = `
vec3 prtSrgbEncode(vec3 linear) {
  vec3 x = clamp(linear, 0.0, 1.0);
  vec3 lo = 12.92 * x;
  vec3 hi = min(vec3(1.0), 1.055 * pow(x, vec3(1.0 / 2.4)) - 0.055);
  return mix(hi, lo, vec3(lessThanEqual(x, vec3(0.0031308))));
}`;

function srgbEncode(x) {
  x = Math.min(Math.max(x, 0), 1);
  return x <= 0.0031308 ? 12.92 * x : Math.min(1, 1.055 * Math.pow(x, 1 / 2.4) - 0.055);
}

export class MeshView {
  /**
   * @param {HTMLCanvasElement} canvas
   * @param {object} camera the pack's camera (Pack.camera())
   * @param {Float32Array} positions 3 floats per vertex
   * @param {Uint32Array} triangles 3 indices per triangle
   */
  constructor(canvas, camera, positions, triangles) {
    this.canvas = canvas;
    // No antialiasing, so that mesh pixels are prt-view's (one sample at each pixel centre). The
    // drawing buffer is not preserved (a copy per frame, 20 % of a frame in software WebGL):
    // screenshots see the composited frame, and meshMask() draws into its own target.
    this.renderer = new THREE.WebGLRenderer({canvas, antialias: false,
                                             preserveDrawingBuffer: false});
    this.renderer.setPixelRatio(1);
    this.renderer.autoClear = true;
    this.scene = new THREE.Scene();

    const eye = new THREE.Vector3(...camera.eye);
    const target = new THREE.Vector3(...camera.target);
    const dist = eye.distanceTo(target);
    this.camera = new THREE.PerspectiveCamera(camera.fov, camera.width / camera.height,
                                              dist * 1e-3, dist * 1e3);
    this.target = target;
    this.camera.position.copy(eye);
    this.camera.up.set(...camera.up);
    this.camera.lookAt(target);
    this.camera.updateMatrixWorld();

    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute('position', new THREE.BufferAttribute(positions, 3));
    this.radiance = new THREE.BufferAttribute(new Float32Array(positions.length), 3);
    this.radiance.setUsage(THREE.DynamicDrawUsage);
    geometry.setAttribute('radiance', this.radiance);
    geometry.setIndex(new THREE.BufferAttribute(triangles, 1));
    this.material = new THREE.ShaderMaterial({
      uniforms: {exposure: {value: 1.0}},
      vertexShader: `
        attribute vec3 radiance;
        varying vec3 vRadiance;
        void main() {
          vRadiance = radiance;
          gl_Position = projectionMatrix * modelViewMatrix * vec4(position, 1.0);
        }`,
      fragmentShader: `
        precision highp float;
        uniform float exposure;
        varying vec3 vRadiance;
        ${kSrgbGlsl}
        void main() { gl_FragColor = vec4(prtSrgbEncode(vRadiance * exposure), 1.0); }`,
      side: THREE.DoubleSide,  // prt-view's rasterizer culls nothing
    });
    this.mesh = new THREE.Mesh(geometry, this.material);
    this.mesh.frustumCulled = false;
    this.scene.add(this.mesh);

    // The mask pass (meshMask): the same geometry in flat white on black.
    this.maskMaterial = new THREE.MeshBasicMaterial({color: 0xffffff, side: THREE.DoubleSide});
    this.background = null;
    this.setSize(camera.width, camera.height);
  }

  setSize(width, height) {
    this.width = width;
    this.height = height;
    this.renderer.setSize(width, height, false);
    this.camera.aspect = width / height;
    this.camera.updateProjectionMatrix();
  }

  /**
   * The environment as background, looked up as prt-view's EnvironmentBackground does: the
   * direction d of a pixel sees the map at R⁻¹d (OpenEXR LatLongMap, +Y up), bilinear.
   */
  setEnvironment(env) {
    const n = env.width * env.height;
    const rgba = new Float32Array(4 * n);
    for (let i = 0; i < n; ++i) {
      rgba[4 * i] = env.rgb[3 * i];
      rgba[4 * i + 1] = env.rgb[3 * i + 1];
      rgba[4 * i + 2] = env.rgb[3 * i + 2];
      rgba[4 * i + 3] = 1;
    }
    const tex = new THREE.DataTexture(rgba, env.width, env.height, THREE.RGBAFormat,
                                      THREE.FloatType);
    const linear = this.renderer.extensions.has('OES_texture_float_linear');
    tex.magFilter = tex.minFilter = linear ? THREE.LinearFilter : THREE.NearestFilter;
    tex.wrapS = tex.wrapT = THREE.ClampToEdgeWrapping;
    tex.generateMipmaps = false;
    tex.needsUpdate = true;
    if (this.background) {
      this.background.material.uniforms.map.value.dispose();
      this.scene.remove(this.background);
    }
    const material = new THREE.ShaderMaterial({
      uniforms: {map: {value: tex}, size: {value: new THREE.Vector2(env.width, env.height)},
                 rotation: {value: 0}, exposure: this.material.uniforms.exposure,
                 projectionInverse: {value: new THREE.Matrix4()},
                 cameraToWorld: {value: new THREE.Matrix4()}},
      vertexShader: `
        varying vec2 vNdc;
        void main() { vNdc = position.xy; gl_Position = vec4(position.xy, 1.0, 1.0); }`,
      fragmentShader: `
        precision highp float;
        uniform sampler2D map;
        uniform mat4 projectionInverse;
        uniform mat4 cameraToWorld;
        uniform vec2 size;
        uniform float rotation;
        uniform float exposure;
        varying vec2 vNdc;
        ${kSrgbGlsl}
        const float kPi = 3.14159265358979;
        void main() {
          vec4 view = projectionInverse * vec4(vNdc, 1.0, 1.0);
          vec3 d = normalize((cameraToWorld * vec4(view.xyz / view.w, 0.0)).xyz);
          float c = cos(-rotation), s = sin(-rotation);
          d = vec3(c * d.x + s * d.z, d.y, -s * d.x + c * d.z);
          float lat = atan(d.y, length(d.xz));
          float lon = (d.x == 0.0 && d.z == 0.0) ? 0.0 : atan(d.x, d.z);
          vec2 px = vec2((lon / (-2.0 * kPi) + 0.5) * (size.x - 1.0),
                         (lat / -kPi + 0.5) * (size.y - 1.0));
          vec3 L = texture2D(map, (px + 0.5) / size).rgb;
          gl_FragColor = vec4(prtSrgbEncode(L * exposure), 1.0);
        }`,
      depthWrite: false,
      depthTest: false,
    });
    this.background = new THREE.Mesh(new THREE.PlaneGeometry(2, 2), material);
    this.background.frustumCulled = false;
    this.background.renderOrder = -1;
    this.scene.add(this.background);
  }

  setExposure(e) {
    this.material.uniforms.exposure.value = e;
  }

  /** Frees the GPU resources and the WebGL context (the page opens another pack). */
  dispose() {
    this.mesh.geometry.dispose();
    this.material.dispose();
    this.maskMaterial.dispose();
    if (this.background) {
      this.background.material.uniforms.map.value.dispose();
      this.background.material.dispose();
      this.background.geometry.dispose();
    }
    this.renderer.dispose();
    this.renderer.forceContextLoss();
  }

  setRotation(radians) {
    if (this.background) this.background.material.uniforms.rotation.value = radians;
  }

  /** Moves the camera's eye (an orbit), still looking at the pack camera's target. */
  setEye(eye) {
    this.camera.position.set(eye[0], eye[1], eye[2]);
    this.camera.lookAt(this.target);
    this.camera.updateMatrixWorld();
  }

  /** Uploads a frame's radiance (3 floats per vertex). */
  setRadiance(rgb) {
    this.radiance.array.set(rgb);
    this.radiance.needsUpdate = true;
  }

  render() {
    if (this.background) {
      const u = this.background.material.uniforms;
      u.projectionInverse.value.copy(this.camera.projectionMatrixInverse);
      u.cameraToWorld.value.copy(this.camera.matrixWorld);
    }
    this.renderer.render(this.scene, this.camera);
  }

  /**
   * Which pixels the mesh covers, rows from the top: 1 byte per pixel (1 mesh, 0 background),
   * from a pass of the same geometry and camera in flat white. Leaves the canvas as it was.
   */
  meshMask() {
    const target = new THREE.WebGLRenderTarget(this.width, this.height);
    const bg = this.background;
    if (bg) bg.visible = false;
    this.mesh.material = this.maskMaterial;
    const clear = this.renderer.getClearColor(new THREE.Color());
    this.renderer.setClearColor(0x000000, 1);
    this.renderer.setRenderTarget(target);
    this.renderer.render(this.scene, this.camera);
    const rgba = new Uint8Array(4 * this.width * this.height);
    this.renderer.readRenderTargetPixels(target, 0, 0, this.width, this.height, rgba);
    this.renderer.setRenderTarget(null);
    this.renderer.setClearColor(clear, 1);
    this.mesh.material = this.material;
    if (bg) bg.visible = true;
    target.dispose();
    const mask = new Uint8Array(this.width * this.height);
    for (let y = 0; y < this.height; ++y) {  // GL rows are bottom-up
      const src = (this.height - 1 - y) * this.width;
      for (let x = 0; x < this.width; ++x) mask[y * this.width + x] = rgba[4 * (src + x)] > 127;
    }
    this.render();
    return mask;
  }
}

/**
 * The environment's radiance seen along direction d under a rotation about +Y, as prt-view's
 * EnvironmentBackground: L(R⁻¹d) from the lat-long map (envmap.cpp LatLongPixelPosition),
 * bilinear between the pixel centres around it (EnvironmentLookup::Bilinear). Writes out[0..2].
 */
function environmentRadiance(env, d, rotation, out) {
  const c = Math.cos(-rotation), s = Math.sin(-rotation);
  const x = c * d[0] + s * d[2], y = d[1], z = -s * d[0] + c * d[2];
  const w = env.width, h = env.height;
  const lat = Math.atan2(y, Math.sqrt(z * z + x * x));
  const lon = z === 0 && x === 0 ? 0 : Math.atan2(x, z);
  const px = Math.min(Math.max((lon / (-2 * Math.PI) + 0.5) * (w - 1), 0), w - 1);
  const py = Math.min(Math.max((lat / -Math.PI + 0.5) * (h - 1), 0), h - 1);
  const x0 = Math.min(Math.floor(px), w - 2), y0 = Math.min(Math.floor(py), h - 2);
  const fx = px - x0, fy = py - y0;
  const i00 = 3 * (y0 * w + x0), i10 = i00 + 3, i01 = i00 + 3 * w, i11 = i01 + 3;
  const w00 = (1 - fx) * (1 - fy), w10 = fx * (1 - fy), w01 = (1 - fx) * fy, w11 = fx * fy;
  for (let k = 0; k < 3; ++k) {
    out[k] = w00 * env.rgb[i00 + k] + w10 * env.rgb[i10 + k] + w01 * env.rgb[i01 + k] +
             w11 * env.rgb[i11 + k];
  }
}

/**
 * An image pack: its samples are the pixels of the baked camera, row-major from the top. Pixels
 * that see no surface (prt_runtime_get_image_background) show the environment, as in prt-view.
 */
export class ImageView {
  constructor(canvas, camera, background, coverage = null) {
    const {width, height} = camera;
    this.canvas = canvas;
    canvas.width = width;
    canvas.height = height;
    // Shown at a whole multiple of its size, pixels as squares (image packs are often small).
    const scale = Math.max(1, Math.floor(640 / Math.max(width, (height * 4) / 3)));
    canvas.style.width = `${scale * width}px`;
    canvas.style.imageRendering = 'pixelated';
    this.width = width;
    this.height = height;
    this.ctx = canvas.getContext('2d');
    this.image = this.ctx.createImageData(width, height);
    this.exposure = 1;
    this.rgb = new Float32Array(3 * width * height);
    this.background = background;  // 1 byte per pixel
    // Supersampled packs: each pixel's surface fraction; (1 − coverage) of the environment is
    // added to a partly covered pixel's radiance (docs/image-relighting.md, "Supersampling").
    this.coverage = coverage;
    this.env = null;
    this.rotation = 0;
    this.backgroundRgb = null;  // the environment at the background pixels, for this rotation
    // The pixel rays (vocabulary/camera_projection.cpp PixelDirection).
    const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2],
                             a[0] * b[1] - a[1] * b[0]];
    const norm = (a) => {
      const l = Math.hypot(a[0], a[1], a[2]);
      return [a[0] / l, a[1] / l, a[2] / l];
    };
    const f = norm(sub(camera.target, camera.eye));
    const r = norm(cross(f, camera.up));
    const u = cross(r, f);
    const t = Math.tan((camera.fov * Math.PI) / 360);
    const aspect = width / height;
    this.direction = (x, y) => {
      const sx = ((2 * (x + 0.5)) / width - 1) * aspect * t;
      const sy = (1 - (2 * (y + 0.5)) / height) * t;
      return norm([f[0] + sx * r[0] + sy * u[0], f[1] + sx * r[1] + sy * u[1],
                   f[2] + sx * r[2] + sy * u[2]]);
    };
  }

  setExposure(e) {
    this.exposure = e;
  }

  setRotation(radians) {
    if (radians !== this.rotation) this.backgroundRgb = null;
    this.rotation = radians;
  }

  /** An image pack's view is fixed: its pixels are the samples. */
  setEye() {}

  setEnvironment(env) {
    this.env = env;
    this.backgroundRgb = null;
  }

  setRadiance(rgb) {
    this.rgb.set(rgb);
  }

  updateBackground() {
    const n = this.width * this.height;
    this.backgroundRgb = new Float32Array(3 * n);
    if (!this.env) return;
    const out = [0, 0, 0];
    for (let p = 0; p < n; ++p) {
      const partial = this.coverage && this.coverage[p] > 0 && this.coverage[p] < 1;
      if (!this.background[p] && !partial) continue;
      environmentRadiance(this.env, this.direction(p % this.width, Math.floor(p / this.width)),
                          this.rotation, out);
      this.backgroundRgb.set(out, 3 * p);
    }
  }

  render() {
    if (!this.backgroundRgb) this.updateBackground();
    const d = this.image.data;
    const e = this.exposure;
    const n = this.width * this.height;
    const c = this.coverage;
    for (let i = 0; i < n; ++i) {
      if (c && c[i] > 0 && c[i] < 1) {
        const share = 1 - c[i];
        for (let k = 0; k < 3; ++k) {
          const v = this.rgb[3 * i + k] + share * this.backgroundRgb[3 * i + k];
          d[4 * i + k] = Math.round(255 * srgbEncode(v * e));
        }
        d[4 * i + 3] = 255;
        continue;
      }
      const src = this.background[i] ? this.backgroundRgb : this.rgb;
      d[4 * i] = Math.round(255 * srgbEncode(src[3 * i] * e));
      d[4 * i + 1] = Math.round(255 * srgbEncode(src[3 * i + 1] * e));
      d[4 * i + 2] = Math.round(255 * srgbEncode(src[3 * i + 2] * e));
      d[4 * i + 3] = 255;
    }
    this.ctx.putImageData(this.image, 0, 0);
  }

  /** Every pixel is the image's (the test compares them all). */
  meshMask() {
    return new Uint8Array(this.width * this.height).fill(1);
  }
  /** The drawn pixels, RGB, rows from the top. */
  pixels() {
    const d = this.ctx.getImageData(0, 0, this.width, this.height).data;
    const rgb = new Uint8Array(3 * this.width * this.height);
    for (let i = 0; i < this.width * this.height; ++i) {
      rgb[3 * i] = d[4 * i];
      rgb[3 * i + 1] = d[4 * i + 1];
      rgb[3 * i + 2] = d[4 * i + 2];
    }
    return rgb;
  }
}
