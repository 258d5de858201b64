// Compressed and quantized variants of a glTF file, made with glTF Transform for baker's tests:
//   node transform.js draco|meshopt|quantize IN OUT
// draco: KHR_draco_mesh_compression (edgebreaker, default quantization); meshopt:
// EXT_meshopt_compression with its filters (level "medium": quantized attributes);
// quantize: KHR_mesh_quantization (UVs dequantized through KHR_texture_transform).
import { NodeIO } from '@gltf-transform/core';
import { ALL_EXTENSIONS } from '@gltf-transform/extensions';
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
const steps = {
  draco: () => draco({ method: 'edgebreaker' }),
  meshopt: () => meshopt({ encoder: MeshoptEncoder, level: 'medium' }),
  quantize: () => quantize(),
};
if (!(variant in steps)) {
  console.error(`unknown variant ${variant}: draco, meshopt or quantize`);
  process.exit(2);
}
await document.transform(steps[variant]());
await io.write(output, document);
