// kiln-lightmap.js: a three.js GLTFLoader plugin that shows kiln's baked lightmaps.
//
//   import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
//   import { KilnLightmapPlugin } from './kiln-lightmap.js';
//   const loader = new GLTFLoader();
//   loader.register((parser) => new KilnLightmapPlugin(parser));
//   const gltf = await loader.loadAsync('out/cornell/cornell_box.gltf');
//
// It reads the node-level MX_lightmap extension that `kiln bake` writes (docs/threejs.md,
// docs/lightmap_outputs.md):
//   "MX_lightmap": {"lightMapTexture": {"index": T, "texCoord": 1}, "scale": [sx, sy],
//                   "offset": [ox, oy], "intensity": I,
//                   "extras": {"kiln": {"page": i, "encoding": "dldr" | "rgbm", "range": R}}}
// atlas UV = TEXCOORD_1 x scale + offset in glTF texture coordinates, irradiance
// E = intensity x decoded sample, where dldr decodes as sRGB (E = I x s.rgb, I = 2 pi) and
// rgbm as linear with rgb x a x 8 (E = I x 8 x s.rgb x s.a, I = pi). A plain MX_lightmap
// (no extras.kiln) reads as dldr.
//
// Per lightmapped node it:
//   - loads texture T through the parser (so .glb images in bufferViews work), clones it for
//     the node (clones share the image: one upload per page) and sets the colour space
//     (sRGB for dldr, linear for rgbm), flipY = false (glTF's convention: v = 0 is the
//     image's first row, as GLTFLoader does for every texture), channel = texCoord, and
//     offset / repeat = offset / scale (three.js's transform with no rotation is
//     uv' = uv x repeat + offset, applied to the glTF coordinates as they are);
//   - clones the node's materials (nodes that share a material have different atlas
//     rectangles) and sets lightMap and lightMapIntensity = intensity;
//   - with the default option `kilnShading`, shades the lightmap the way `kiln render` does:
//     outgoing radiance = emission + base colour x E / pi (docs/render.md), whatever metallic
//     and roughness say. three.js's own rule takes (1 - metalness) x base colour and takes
//     the share of its 4% dielectric specular lobe off the diffuse without adding specular
//     back (a lightmap has no direction): a rough dielectric comes out 1-2% darker than
//     kiln render (docs/threejs.md) and a metal black. rgbm pages are decoded (rgb x a x
//     range) in the same shader patch, which rgbm needs in any case;
//   - with `tintedTransparency` (default), lets the light behind an alphaMode BLEND material
//     of uniform colour through tinted by its base colour, as kiln's bake and kiln render
//     do (alpha x surface + (1 - alpha) x base colour x behind): blending with a constant
//     colour. A BLEND material with a base colour texture keeps three.js's
//     alpha x surface + (1 - alpha) x behind (WebGL cannot blend with a per-pixel tint);
//   - hides (visible = false) every KHR_lights_punctual light whose extras.kiln.baked is true:
//     its light is already in the lightmaps (option `hideBakedLights`, default true).
//     Lights the bake left to run time (mixed lights under baked-indirect and shadowmask)
//     stay on.
// Per probe-lit node (an object too small for a lightmap, which `kiln bake` lights with its own
// probe light instead: extras.kiln.probeSH, 27 numbers, the 9 L2 radiance SH coefficients of
// kiln's basis, each R, G, B; docs/lightmap_outputs.md) it clones the node's materials and
// adds the irradiance E = shGetIrradianceAt(world normal, SH) (three.js's L2 irradiance, the
// same convolution as kiln's probeIrradiance), clamped at 0, as kiln render does: with
// `kilnShading`, outgoing radiance += base colour x E / pi; without it, E goes into three.js's
// own indirect irradiance. The SH is a per-material uniform (kilnProbeSH), so every probe-lit
// material shares one shader program. mesh.userData.kilnProbeSH holds the SH.
// Errors in the extension (a missing texture, an unknown encoding, a node without the UV set)
// or in extras.kiln.probeSH are reported with console.warn naming the node and the field; that
// node keeps its material and the rest of the file loads.
import {
  ConstantColorFactor,
  CustomBlending,
  LinearSRGBColorSpace,
  OneFactor,
  OneMinusSrcAlphaFactor,
  SRGBColorSpace,
  ShaderChunk,
  SrcAlphaFactor,
  Vector3,
} from 'three';

export const EXTENSION_NAME = 'MX_lightmap';

const DEFAULT_OPTIONS = { kilnShading: true, tintedTransparency: true, hideBakedLights: true };

// three.js's name of glTF TEXCOORD_n.
function uvAttributeName(texCoord) {
  return texCoord === 0 ? 'uv' : 'uv' + texCoord;
}

function finiteArray(value, length) {
  return Array.isArray(value) && value.length === length &&
      value.every((v) => typeof v === 'number' && Number.isFinite(v));
}

// Validates a node's extension; returns {texture, texCoord, scale, offset, intensity,
// encoding} or a string that says what is wrong.
export function readLightmapExtension(ext, textureCount) {
  if (typeof ext !== 'object' || ext === null) return 'expected an object';
  const t = ext.lightMapTexture;
  if (typeof t !== 'object' || t === null || !Number.isInteger(t.index) || t.index < 0 ||
      t.index >= textureCount)
    return `lightMapTexture.index: expected a texture index below ${textureCount}`;
  const texCoord = t.texCoord === undefined ? 0 : t.texCoord;
  if (!Number.isInteger(texCoord) || texCoord < 0 || texCoord > 3)
    return 'lightMapTexture.texCoord: expected an integer 0..3';
  const scale = ext.scale === undefined ? [1, 1] : ext.scale;
  const offset = ext.offset === undefined ? [0, 0] : ext.offset;
  if (!finiteArray(scale, 2)) return 'scale: expected 2 finite numbers';
  if (!finiteArray(offset, 2)) return 'offset: expected 2 finite numbers';
  const intensity = ext.intensity === undefined ? 1 : ext.intensity;
  if (typeof intensity !== 'number' || !Number.isFinite(intensity) || intensity < 0)
    return 'intensity: expected a finite number >= 0';
  const kiln = ext.extras && ext.extras.kiln;
  const encoding = kiln && kiln.encoding !== undefined ? kiln.encoding : 'dldr';
  if (encoding !== 'dldr' && encoding !== 'rgbm')
    return `extras.kiln.encoding: "${encoding}" is not dldr or rgbm`;
  const range = kiln && kiln.range !== undefined ? kiln.range : encoding === 'rgbm' ? 8 : 2;
  if (typeof range !== 'number' || !(range > 0)) return 'extras.kiln.range: expected a number > 0';
  return { texture: t.index, texCoord, scale, offset, intensity, encoding, range };
}

// The lightmap term of lights_fragment_maps, replaced. kiln: outgoing radiance gets
// base colour x E / pi (BRDF_Lambert), E = decoded sample x lightMapIntensity; rgbm decodes
// rgb x a x range first. The rest of the chunk (environment maps) is kept.
const THREE_LIGHTMAP_TERM = /vec4 lightMapTexel = texture2D\( lightMap, vLightMapUv \);\s*vec3 lightMapIrradiance = lightMapTexel\.rgb \* lightMapIntensity;\s*irradiance \+= lightMapIrradiance;/;

function lightmapTerm(encoding, range, kilnShading) {
  const decode = encoding === 'rgbm'
    ? `lightMapTexel.rgb * lightMapTexel.a * ${range.toFixed(6)}`
    : 'lightMapTexel.rgb';
  const add = kilnShading
    ? 'reflectedLight.indirectDiffuse += lightMapIrradiance * BRDF_Lambert( diffuseColor.rgb );'
    : 'irradiance += lightMapIrradiance;';
  return `vec4 lightMapTexel = texture2D( lightMap, vLightMapUv );
		vec3 lightMapIrradiance = ${decode} * lightMapIntensity;
		${add}`;
}

// Sets the shader patch on a (cloned) material. Returns an error message, or null.
function patchMaterial(material, encoding, range, kilnShading) {
  if (!material.isMeshStandardMaterial && !material.isMeshLambertMaterial &&
      !material.isMeshPhongMaterial) {
    // Unlit materials (KHR_materials_unlit) have no lightmap term of their own to patch;
    // three.js's own lightMap handling is all a dldr page needs there.
    return encoding === 'dldr' ? null : `rgbm needs a lit material, not a ${material.type}`;
  }
  const source = ShaderChunk.lights_fragment_maps;
  if (!THREE_LIGHTMAP_TERM.test(source))
    return 'this three.js build\'s lights_fragment_maps has no lightmap term that ' +
           'kiln-lightmap.js knows (written for r155..r187)';
  const patched = source.replace(THREE_LIGHTMAP_TERM, lightmapTerm(encoding, range, kilnShading));
  const previous = material.onBeforeCompile;
  material.onBeforeCompile = (shader, renderer) => {
    if (previous) previous.call(material, shader, renderer);
    // BRDF_Lambert and reflectedLight exist in every lit material's fragment shader.
    shader.fragmentShader =
        shader.fragmentShader.replace('#include <lights_fragment_maps>', patched);
  };
  const key = `kiln-lightmap:${encoding}:${range}:${kilnShading}`;
  const previousKey = material.customProgramCacheKey.bind(material);
  material.customProgramCacheKey = () => previousKey() + key;
  return null;
}

// Validates a node's extras.kiln.probeSH; returns 9 Vector3 (radiance SH, kiln's basis) or a
// string that says what is wrong.
export function readProbeSh(value) {
  if (!finiteArray(value, 27)) return 'expected 27 finite numbers (9 SH coefficients x R, G, B)';
  const sh = [];
  for (let i = 0; i < 9; ++i) sh.push(new Vector3(value[3 * i], value[3 * i + 1], value[3 * i + 2]));
  return sh;
}

// The probe light's term, after three.js's lights_fragment_maps: the irradiance for the
// unperturbed normal (kiln's preview shades with the interpolated vertex normal) in world
// axes, kiln's probeIrradiance convention (shGetIrradianceAt's constants are pi x Y_00,
// 2 pi / 3 x Y_1m and pi / 4 x Y_2m, kiln's convolution of radiance SH).
function probeTerm(kilnShading) {
  const add = kilnShading
    ? 'reflectedLight.indirectDiffuse += kilnProbeIrradiance * BRDF_Lambert( diffuseColor.rgb );'
    : 'irradiance += kilnProbeIrradiance;';
  return `
#if defined( RE_IndirectDiffuse )
	vec3 kilnProbeIrradiance = max( shGetIrradianceAt( normalize( inverseTransformDirection( nonPerturbedNormal, viewMatrix ) ), kilnProbeSH ), vec3( 0.0 ) );
	${add}
#endif
`;
}

// Sets the probe light's shader patch on a (cloned) material. Returns an error message, or null.
function patchProbeMaterial(material, sh, kilnShading) {
  if (!material.isMeshStandardMaterial && !material.isMeshLambertMaterial &&
      !material.isMeshPhongMaterial)
    return `an unlit ${material.type} takes no probe light`;
  const previous = material.onBeforeCompile;
  material.onBeforeCompile = (shader, renderer) => {
    if (previous) previous.call(material, shader, renderer);
    shader.uniforms.kilnProbeSH = { value: sh };
    shader.fragmentShader = shader.fragmentShader
        .replace('#include <lights_pars_begin>', '#include <lights_pars_begin>\nuniform vec3 kilnProbeSH[ 9 ];')
        .replace('#include <lights_fragment_maps>', '#include <lights_fragment_maps>\n' + probeTerm(kilnShading));
  };
  const key = `kiln-probe:${kilnShading}`;
  const previousKey = material.customProgramCacheKey.bind(material);
  material.customProgramCacheKey = () => previousKey() + key;
  return null;
}

export class KilnLightmapPlugin {
  constructor(parser, options = {}) {
    this.parser = parser;
    this.name = EXTENSION_NAME;
    this.options = { ...DEFAULT_OPTIONS, ...options };
    this.pages = new Map();  // texture index -> Promise<Texture>
  }

  _warn(nodeIndex, message) {
    const node = this.parser.json.nodes[nodeIndex];
    const name = node && node.name !== undefined ? ` ("${node.name}")` : '';
    console.warn(`KilnLightmapPlugin: nodes[${nodeIndex}]${name}.extensions.${EXTENSION_NAME}.` +
                 message + '; the node is shown without its lightmap');
  }

  _page(index) {
    if (!this.pages.has(index)) this.pages.set(index, this.parser.getDependency('texture', index));
    return this.pages.get(index);
  }

  createNodeMesh(nodeIndex) {
    const json = this.parser.json;
    const nodeDef = json.nodes[nodeIndex];
    if (nodeDef.mesh === undefined) return null;
    if (!nodeDef.extensions || !nodeDef.extensions[EXTENSION_NAME]) {
      const kiln = nodeDef.extras && nodeDef.extras.kiln;
      if (!kiln || kiln.probeSH === undefined) return null;
      return this._probeLit(nodeIndex);
    }
    // Another plugin's mesh (GPU instancing) if it has one for this node, else the parser's.
    const instancing = this.parser.plugins.EXT_mesh_gpu_instancing;
    const meshPromise = (instancing && instancing.createNodeMesh(nodeIndex)) ||
                        this.parser.createNodeMesh(nodeIndex);
    const spec = readLightmapExtension(nodeDef.extensions[EXTENSION_NAME],
                                       (json.textures || []).length);
    if (typeof spec === 'string') {
      this._warn(nodeIndex, spec);
      return meshPromise;
    }
    return Promise.all([meshPromise, this._page(spec.texture)]).then(([object, page]) => {
      this._apply(nodeIndex, object, page, spec);
      return object;
    }, (error) => {
      // A texture that does not load leaves the mesh as it is.
      this._warn(nodeIndex, `lightMapTexture: texture ${spec.texture} did not load (${error})`);
      return meshPromise;
    });
  }

  // A probe-lit node: its materials lit by its extras.kiln.probeSH.
  _probeLit(nodeIndex) {
    const instancing = this.parser.plugins.EXT_mesh_gpu_instancing;
    const meshPromise = (instancing && instancing.createNodeMesh(nodeIndex)) ||
                        this.parser.createNodeMesh(nodeIndex);
    const sh = readProbeSh(this.parser.json.nodes[nodeIndex].extras.kiln.probeSH);
    if (typeof sh === 'string') {
      this._warnProbe(nodeIndex, sh);
      return meshPromise;
    }
    return Promise.resolve(meshPromise).then((object) => {
      const meshes = [];
      object.traverse((o) => { if (o.isMesh) meshes.push(o); });
      const { kilnShading } = this.options;
      for (const mesh of meshes) {
        const lit = (material) => {
          const m = material.clone();
          const error = patchProbeMaterial(m, sh, kilnShading);
          if (error) {
            this._warnProbe(nodeIndex, error);
            return material;
          }
          m.needsUpdate = true;
          return m;
        };
        mesh.material = Array.isArray(mesh.material) ? mesh.material.map(lit) : lit(mesh.material);
        mesh.userData.kilnProbeSH = sh.map((v) => v.toArray());
      }
      return object;
    });
  }

  _warnProbe(nodeIndex, message) {
    const node = this.parser.json.nodes[nodeIndex];
    const name = node && node.name !== undefined ? ` ("${node.name}")` : '';
    console.warn(`KilnLightmapPlugin: nodes[${nodeIndex}]${name}.extras.kiln.probeSH: ${message}` +
                 '; the node is shown without its probe light');
  }

  _apply(nodeIndex, object, page, spec) {
    const meshes = [];
    object.traverse((o) => { if (o.isMesh) meshes.push(o); });
    const attribute = uvAttributeName(spec.texCoord);
    const texture = page.clone();
    texture.flipY = false;
    texture.colorSpace = spec.encoding === 'rgbm' ? LinearSRGBColorSpace : SRGBColorSpace;
    texture.channel = spec.texCoord;
    texture.repeat.set(spec.scale[0], spec.scale[1]);
    texture.offset.set(spec.offset[0], spec.offset[1]);
    texture.rotation = 0;
    texture.center.set(0, 0);
    texture.matrixAutoUpdate = true;
    texture.needsUpdate = true;
    const { kilnShading, tintedTransparency } = this.options;
    for (const mesh of meshes) {
      if (!mesh.geometry.attributes[attribute]) {
        this._warn(nodeIndex, `lightMapTexture.texCoord: the mesh has no TEXCOORD_${spec.texCoord}`);
        continue;
      }
      const lightmapped = (material) => {
        const m = material.clone();
        m.lightMap = texture;
        m.lightMapIntensity = spec.intensity;
        const error = patchMaterial(m, spec.encoding, spec.range, kilnShading);
        if (error) {
          this._warn(nodeIndex, `extras.kiln.encoding: ${error}`);
          return material;
        }
        if (tintedTransparency && m.transparent && !m.map && !m.vertexColors) {
          // alpha x surface + (1 - alpha) x base colour x behind.
          m.blending = CustomBlending;
          m.blendSrc = SrcAlphaFactor;
          m.blendDst = ConstantColorFactor;
          m.blendSrcAlpha = OneFactor;
          m.blendDstAlpha = OneMinusSrcAlphaFactor;
          m.blendColor.copy(m.color).multiplyScalar(1 - Math.min(Math.max(m.opacity, 0), 1));
        }
        m.needsUpdate = true;
        return m;
      };
      mesh.material = Array.isArray(mesh.material) ? mesh.material.map(lightmapped)
                                                    : lightmapped(mesh.material);
      mesh.userData.kilnLightmap = { page: spec.texture, encoding: spec.encoding,
                                     scale: spec.scale, offset: spec.offset };
    }
  }

  afterRoot(result) {
    if (!this.options.hideBakedLights) return null;
    for (const scene of result.scenes) {
      scene.traverse((o) => {
        const kiln = o.isLight && o.userData && o.userData.kiln;
        if (kiln && kiln.baked === true) o.visible = false;
      });
    }
    return null;
  }
}
