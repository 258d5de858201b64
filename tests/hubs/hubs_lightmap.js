// MOZ_lightmap as the Hubs client reads it, for tests/test_browser.py.
//
// Written for these tests after Hubs' GLTFHubsLightMapExtension (MPL-2.0,
// https://github.com/Hubs-Foundation/hubs, src/components/gltf-model-plus.js), which does this:
// a GLTFLoader loadMaterial hook that loads the material as usual, then sets its lightMap to the
// texture at MOZ_lightmap.index and its lightMapIntensity to MOZ_lightmap.intensity (1 when
// absent), times pi for an unlit (MeshBasicMaterial) one. What it leaves out is what the
// test measures: texCoord is not read (three.js r141 samples every lightMap from uv2, i.e.
// TEXCOORD_1) and the texture keeps the loader's default linear encoding (texel / 255).

export class HubsLightmapExtension {
  constructor(parser) {
    this.parser = parser;
    this.name = 'MOZ_lightmap';
  }

  loadMaterial(materialIndex) {
    const definition = this.parser.json.materials[materialIndex];
    const extension = (definition.extensions || {})[this.name];
    if (!extension) return null;
    return Promise.all([
      this.parser.loadMaterial(materialIndex),
      this.parser.getDependency('texture', extension.index),
    ]).then(([material, lightMap]) => {
      material.lightMap = lightMap;
      material.lightMapIntensity = extension.intensity === undefined ? 1 : extension.intensity;
      if (material.isMeshBasicMaterial) material.lightMapIntensity *= Math.PI;
      return material;
    });
  }
}
