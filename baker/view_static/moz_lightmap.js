// A GLTFLoader plugin for MOZ_lightmap, as baker writes it (docs/output.md), and for its
// directional pages, BAKER_lightmap_directional (docs/directional.md).
//
// {"extensions": {"MOZ_lightmap": {"index": T, "texCoord": n, "intensity": s}}} on a material
// becomes three.js's lightMap (texture T read from TEXCOORD_n) with lightMapIntensity s.
// The texels decode by the file's asset.extras.baker.lightmap_encoding: "linear" (texel/255,
// what Hubs and the three.js plugin have always done; the default) or "srgb" (the extension
// text). three.js shades a lightmap as irradiance: diffuse colour x lightMap x intensity / pi.
//
// {"BAKER_lightmap_directional": {"index": D, "texCoord": n}} beside it (on normal-mapped
// materials) holds, per lightmap texel, h = g / (1 + |g|) as 0.5 + 0.5 h (linear), on the
// lightmap's UV set. The shader patch below decodes g and scales the lightmap's irradiance by
// max(0, 1 + (n - n0) . g), with n the normal-mapped world normal and n0 the interpolated
// vertex one (baker/light/directional.py; baker preview computes the same). World space is the
// glTF scene's: add the loaded scene without a transform of its own.
//
// In an app of your own (`baker plugin DIR` writes this file; three.js r151 or later):
//   import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';
//   import { MozLightmapPlugin } from './moz_lightmap.js';
//   const loader = new GLTFLoader().register((parser) => new MozLightmapPlugin(parser));

import { NoColorSpace, SRGBColorSpace } from 'three';

const DIRECTIONAL = 'BAKER_lightmap_directional';

const DECODE = `
#if defined( RE_IndirectDiffuse ) && defined( USE_LIGHTMAP )
{
  vec3 bakerH = texture2D( bakerDirectionMap, vLightMapUv ).rgb * 2.0 - 1.0;
  vec3 bakerG = bakerH / max( 1.0 - length( bakerH ), 1e-6 );
  vec3 bakerN = inverseTransformDirection( normal, viewMatrix );
  vec3 bakerN0 = inverseTransformDirection( nonPerturbedNormal, viewMatrix );
  float bakerFactor = max( 0.0, 1.0 + faceDirection * dot( bakerN - bakerN0, bakerG ) );
  irradiance += lightMapIrradiance * ( bakerFactor - 1.0 );
}
#endif`;

// The material's shader with the directional decode after three.js's lightmap term.
function directionalShader(texture) {
  return (shader) => {
    shader.uniforms.bakerDirectionMap = { value: texture };
    shader.fragmentShader = shader.fragmentShader
      .replace('#include <lightmap_pars_fragment>',
        '#include <lightmap_pars_fragment>\nuniform sampler2D bakerDirectionMap;')
      .replace('#include <lights_fragment_maps>', `#include <lights_fragment_maps>${DECODE}`);
  };
}

export class MozLightmapPlugin {
  constructor(parser) {
    this.parser = parser;
    this.name = 'MOZ_lightmap';
    const baker = ((parser.json.asset || {}).extras || {}).baker || {};
    this.colorSpace = baker.lightmap_encoding === 'srgb' ? SRGBColorSpace : NoColorSpace;
  }

  extendMaterialParams(materialIndex, params) {
    const material = this.parser.json.materials[materialIndex];
    const extensions = material.extensions || {};
    const extension = extensions[this.name];
    if (!extension || extension.index === undefined) return Promise.resolve();
    params.lightMapIntensity = extension.intensity === undefined ? 1 : extension.intensity;
    const pending = [this.parser.assignTexture(params, 'lightMap',
      { index: extension.index, texCoord: extension.texCoord || 0 }, this.colorSpace)];
    const directional = extensions[DIRECTIONAL];
    if (directional && directional.index !== undefined) {
      pending.push(this.parser.getDependency('texture', directional.index).then((texture) => {
        texture.colorSpace = NoColorSpace;
        params.onBeforeCompile = directionalShader(texture);
        params.customProgramCacheKey = () => DIRECTIONAL;
      }));
    }
    return Promise.all(pending);
  }
}
