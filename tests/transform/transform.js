// Variants of a glTF file, made with glTF Transform for baker's tests:
//   node transform.js draco|meshopt|quantize|texture-transform|animated|emissive IN OUT
// draco: KHR_draco_mesh_compression (edgebreaker, default quantization); meshopt:
// EXT_meshopt_compression with its filters (level "medium": quantized attributes);
// quantize: KHR_mesh_quantization (UVs dequantized through KHR_texture_transform);
// texture-transform: every base colour and emissive texture read through a
// KHR_texture_transform (offset, scale), TEXCOORD_0 stored inverted so the file looks the same;
// animated: an animation turning the first mesh node about +Y, its rest pose the file's;
// emissive: the last material that did not glow (else the last) gets 0.5, 0.3, 0.1 more emission.
import { NodeIO } from '@gltf-transform/core';
import { ALL_EXTENSIONS, KHRTextureTransform } from '@gltf-transform/extensions';
import { draco, meshopt, quantize } from '@gltf-transform/functions';
import draco3d from 'draco3dgltf';
import { MeshoptDecoder, MeshoptEncoder } from 'meshoptimizer';

const [variant, input, output] = process.argv.slice(2);
await MeshoptDecoder.ready;
await MeshoptEncoder.ready;
const io = new NodeIO().registerExtensions(ALL_EXTENSIONS).registerDependencies({
  'draco3d.decoder': await draco3d.createDecoderModule(),
  'draco3d.encoder': await draco3d.createEncoderModule(),
  'meshopt.decoder': MeshoptDecoder,
  'meshopt.encoder': MeshoptEncoder,
});
const document = await io.read(input);
const OFFSET = [0.25, -0.5];
const SCALE = [2.0, 0.5];

// uv_texture = offset + scale * uv_stored (no rotation): store (uv - offset) / scale.
function textureTransform() {
  return (doc) => {
    const extension = doc.createExtension(KHRTextureTransform);
    const moved = new Set();
    for (const mesh of doc.getRoot().listMeshes()) {
      for (const prim of mesh.listPrimitives()) {
        const material = prim.getMaterial();
        const uv = prim.getAttribute('TEXCOORD_0');
        if (!material || !uv) continue;
        const infos = [material.getBaseColorTextureInfo(), material.getEmissiveTextureInfo()]
          .filter((info, k) => info && [material.getBaseColorTexture(),
            material.getEmissiveTexture()][k] && info.getTexCoord() === 0);
        if (!infos.length) continue;
        for (const info of infos) {
          info.setExtension('KHR_texture_transform',
            extension.createTransform().setOffset(OFFSET).setScale(SCALE));
        }
        if (moved.has(uv)) continue;
        moved.add(uv);
        const values = uv.getArray().slice();
        for (let i = 0; i < values.length; i += 2) {
          values[i] = (values[i] - OFFSET[0]) / SCALE[0];
          values[i + 1] = (values[i + 1] - OFFSET[1]) / SCALE[1];
        }
        uv.setArray(values);
      }
    }
  };
}

function animated() {
  return (doc) => {
    const node = doc.getRoot().listNodes().find((n) => n.getMesh());
    const rest = node.getRotation();
    const half = Math.SQRT1_2; // a quarter turn about +Y, after the rest rotation
    const times = doc.createAccessor().setType('SCALAR').setArray(new Float32Array([0, 1]));
    const values = doc.createAccessor().setType('VEC4')
      .setArray(new Float32Array([...rest, ...quatMultiply([0, half, 0, half], rest)]));
    const buffer = doc.getRoot().listBuffers()[0];
    times.setBuffer(buffer);
    values.setBuffer(buffer);
    const sampler = doc.createAnimationSampler().setInput(times).setOutput(values)
      .setInterpolation('LINEAR');
    const channel = doc.createAnimationChannel().setTargetNode(node).setTargetPath('rotation')
      .setSampler(sampler);
    doc.createAnimation('turn').addSampler(sampler).addChannel(channel);
  };
}

function quatMultiply([ax, ay, az, aw], [bx, by, bz, bw]) {
  return [aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
    aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz];
}

function emissive() {
  return (doc) => {
    const materials = doc.getRoot().listMaterials();
    const dark = materials.filter((m) => m.getEmissiveFactor().every((v) => v === 0));
    const material = dark.length ? dark[dark.length - 1] : materials[materials.length - 1];
    const glow = [0.5, 0.3, 0.1]; // added: the variant only ever adds light
    material.setEmissiveFactor(material.getEmissiveFactor().map((v, k) => Math.min(1, v + glow[k])));
  };
}

const steps = {
  draco: () => draco({ method: 'edgebreaker' }),
  meshopt: () => meshopt({ encoder: MeshoptEncoder, level: 'medium' }),
  quantize: () => quantize(),
  'texture-transform': textureTransform,
  animated,
  emissive,
};
if (!(variant in steps)) {
  console.error(`unknown variant ${variant}: ${Object.keys(steps).join(', ')}`);
  process.exit(2);
}
await document.transform(steps[variant]());
await io.write(output, document);
