// kiln-display.js: renders a three.js scene the way `kiln render` makes its PNG, so that a
// bake looks the same in the browser as in kiln's preview (docs/render.md, "Display"):
//   1. the scene is drawn into a linear floating-point render target (no tone mapping, no
//      sRGB encoding in the materials' shaders), so that transparent surfaces blend in
//      linear radiance, as kiln render composites them;
//   2. a full-screen pass takes radiance x 2^exposure, applies the ACES filmic curve in
//      Narkowicz's fit, x (2.51 x + 0.03) / (x (2.43 x + 0.59) + 0.14) clamped to [0, 1], per
//      channel, and the sRGB transfer function, into the canvas.
// three.js's own ACESFilmicToneMapping is a different fit (Hill's RRT + ODT with a 1/0.6
// exposure), hence this pass.
//
//   const display = new KilnDisplay(renderer, { exposure: 0 });
//   display.setSize(width, height);
//   display.render(scene, camera);          // every frame
//   const linear = display.readLinear();    // Float32Array RGBA, row 0 at the top
import {
  FloatType,
  HalfFloatType,
  LinearSRGBColorSpace,
  Mesh,
  NoToneMapping,
  OrthographicCamera,
  PlaneGeometry,
  RGBAFormat,
  Scene,
  ShaderMaterial,
  WebGLRenderTarget,
} from 'three';

const displayVertex = /* glsl */`
varying vec2 vUv;
void main() {
  vUv = uv;
  gl_Position = vec4(position.xy, 0.0, 1.0);
}`;

const displayFragment = /* glsl */`
uniform sampler2D radiance;
uniform float exposureScale;
varying vec2 vUv;
vec3 acesNarkowicz(vec3 x) {
  x = max(x, vec3(0.0));
  return clamp(x * (2.51 * x + 0.03) / (x * (2.43 * x + 0.59) + 0.14), 0.0, 1.0);
}
vec3 srgbFromLinear(vec3 c) {
  vec3 low = c * 12.92;
  vec3 high = 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055;
  return mix(high, low, vec3(lessThanEqual(c, vec3(0.0031308))));
}
void main() {
  vec3 c = texture2D(radiance, vUv).rgb * exposureScale;
  gl_FragColor = vec4(srgbFromLinear(acesNarkowicz(c)), 1.0);
}`;

// The same curve on the CPU (for images read back with readLinear).
export function acesNarkowicz(x) {
  if (!(x > 0)) return 0;
  const y = (x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14);
  return Math.min(Math.max(y, 0), 1);
}

export function srgbFromLinear(c) {
  return c <= 0.0031308 ? 12.92 * c : 1.055 * Math.pow(c, 1 / 2.4) - 0.055;
}

export class KilnDisplay {
  // options.exposure: EV (radiance x 2^EV); options.float32: a 32-bit float target (exact
  // readback; needs EXT_float_blend for transparent surfaces) instead of half floats.
  constructor(renderer, options = {}) {
    this.renderer = renderer;
    this.exposure = options.exposure || 0;
    this.target = new WebGLRenderTarget(1, 1, {
      type: options.float32 ? FloatType : HalfFloatType,
      format: RGBAFormat,
      colorSpace: LinearSRGBColorSpace,
      depthBuffer: true,
      samples: 0,
    });
    this.material = new ShaderMaterial({
      uniforms: { radiance: { value: this.target.texture }, exposureScale: { value: 1 } },
      vertexShader: displayVertex,
      fragmentShader: displayFragment,
      depthTest: false,
      depthWrite: false,
      toneMapped: false,
    });
    this.quadScene = new Scene();
    this.quadScene.add(new Mesh(new PlaneGeometry(2, 2), this.material));
    this.quadCamera = new OrthographicCamera(-1, 1, 1, -1, 0, 1);
  }

  setSize(width, height) {
    this.target.setSize(width, height);
  }

  render(scene, camera) {
    const r = this.renderer;
    const toneMapping = r.toneMapping;
    r.toneMapping = NoToneMapping;
    r.setRenderTarget(this.target);
    r.render(scene, camera);
    r.setRenderTarget(null);
    this.material.uniforms.exposureScale.value = Math.pow(2, this.exposure);
    r.render(this.quadScene, this.quadCamera);
    r.toneMapping = toneMapping;
  }

  // The linear radiance of the last render: Float32Array of width x height x 4, row 0 at the
  // top (WebGL reads bottom-up; flipped here).
  readLinear() {
    const { width, height } = this.target;
    const floats = this.target.texture.type === FloatType;
    const raw = floats ? new Float32Array(width * height * 4) : new Uint16Array(width * height * 4);
    this.renderer.readRenderTargetPixels(this.target, 0, 0, width, height, raw);
    const out = new Float32Array(width * height * 4);
    const half = (h) => {
      const s = h & 0x8000 ? -1 : 1, e = (h >> 10) & 0x1f, m = h & 0x3ff;
      if (e === 0) return s * Math.pow(2, -14) * (m / 1024);
      if (e === 31) return m ? NaN : s * Infinity;
      return s * Math.pow(2, e - 15) * (1 + m / 1024);
    };
    for (let y = 0; y < height; ++y) {
      const src = (height - 1 - y) * width * 4, dst = y * width * 4;
      for (let i = 0; i < width * 4; ++i)
        out[dst + i] = floats ? raw[src + i] : half(raw[src + i]);
    }
    return out;
  }

  dispose() {
    this.target.dispose();
    this.material.dispose();
    this.quadScene.children[0].geometry.dispose();
  }
}
