// A GLTFLoader plugin for MOZ_lightmap, as baker writes it (docs/output.md).
//
// {"extensions": {"MOZ_lightmap": {"index": T, "texCoord": n, "intensity": s}}} on a material
// becomes three.js's lightMap (texture T read from TEXCOORD_n) with lightMapIntensity s.
// The texels decode by the file's asset.extras.baker.lightmap_encoding: "linear" (texel/255,
// what Hubs and the three.js plugin have always done; the default) or "srgb" (the extension
// text). three.js shades a lightmap as irradiance: diffuse colour x lightMap x intensity / pi.

import { NoColorSpace, SRGBColorSpace } from './three.min.js';

export class MozLightmapPlugin {
  constructor(parser) {
    this.parser = parser;
    this.name = 'MOZ_lightmap';
    const baker = ((parser.json.asset || {}).extras || {}).baker || {};
    this.colorSpace = baker.lightmap_encoding === 'srgb' ? SRGBColorSpace : NoColorSpace;
  }

  extendMaterialParams(materialIndex, params) {
    const material = this.parser.json.materials[materialIndex];
    const extension = (material.extensions || {})[this.name];
    if (!extension || extension.index === undefined) return Promise.resolve();
    params.lightMapIntensity = extension.intensity === undefined ? 1 : extension.intensity;
    return this.parser.assignTexture(params, 'lightMap',
      { index: extension.index, texCoord: extension.texCoord || 0 }, this.colorSpace);
  }
}
