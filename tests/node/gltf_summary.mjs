// node gltf_summary.mjs FILE.glb: what three.js's GLTFLoader reads, as JSON on stdout
// (node names, skinned meshes, materials, each animation's name, duration and tracks).
// Run with NODE_PATH-free resolution: the test puts this file beside node_modules/three.
import { readFileSync } from "node:fs";
import { GLTFLoader } from "three/examples/jsm/loaders/GLTFLoader.js";

const bytes = readFileSync(process.argv[2]);
const buffer = bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength);
new GLTFLoader().parse(
  buffer,
  "",
  (gltf) => {
    const nodes = [];
    const skinned = [];
    const materials = new Set();
    gltf.scene.traverse((object) => {
      nodes.push(object.name);
      if (object.isSkinnedMesh) {
        skinned.push({ name: object.name, bones: object.skeleton.bones.map((b) => b.name) });
      }
      if (object.material) materials.add(object.material.name);
    });
    const animations = gltf.animations.map((clip) => ({
      name: clip.name,
      duration: clip.duration,
      tracks: clip.tracks.map((t) => t.name),
      keys: Math.max(...clip.tracks.map((t) => t.times.length)),
    }));
    process.stdout.write(
      JSON.stringify({ nodes, skinned, materials: [...materials], animations }) + "\n"
    );
  },
  (error) => {
    process.stderr.write(String(error && error.stack ? error.stack : error) + "\n");
    process.exit(1);
  }
);
