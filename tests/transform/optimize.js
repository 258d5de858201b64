// What a pipeline's clean-up does to a baked file, as `gltf-transform optimize` does it:
//   node optimize.js IN OUT
// The same document steps as the CLI's optimize (glTF Transform 4.5), in its order, less the
// ones that need native tools or change the picture on purpose (simplify, texture compression)
// and the mesh compression (tests/transform/transform.js has draco and meshopt on their own):
// dedup, instance, palette, flatten, join, weld, resample, prune, sparse.
import { NodeIO } from '@gltf-transform/core';
import { ALL_EXTENSIONS } from '@gltf-transform/extensions';
import {
  dedup, flatten, instance, join, palette, prune, resample, sparse, weld,
} from '@gltf-transform/functions';

const [input, output] = process.argv.slice(2);
const io = new NodeIO().registerExtensions(ALL_EXTENSIONS);
const document = await io.read(input);
await document.transform(
  dedup(), instance(), palette(), flatten(), join(), weld(), resample(), prune(), sparse(),
);
await io.write(output, document);
