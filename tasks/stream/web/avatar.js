// The user's character in the dancer page (sm export-web --rig): the skinned glTF / VRM loaded by three.js's
// GLTFLoader, its bones driven each frame from the dancer's SMPL-24 joints by the plan Python wrote
// (skeleton_mamba.tasks.motion.retarget.live: the same steps as apply_live_plan, tested against it).
import * as THREE from 'three';
import { GLTFLoader } from 'sm-gltf';

const m3 = rows => new THREE.Matrix4().set(
  rows[0][0], rows[0][1], rows[0][2], 0, rows[1][0], rows[1][1], rows[1][2], 0,
  rows[2][0], rows[2][1], rows[2][2], 0, 0, 0, 0, 1);
const m4 = rows => new THREE.Matrix4().set(...rows.flat());

// (primary, secondary) -> the frame whose columns are primary, secondary made orthogonal, their cross.
function frame(primary, secondary) {
  const e1 = primary.clone().normalize();
  const e2 = secondary.clone().addScaledVector(e1, -secondary.dot(e1)).normalize();
  return new THREE.Matrix4().makeBasis(e1, e2, new THREE.Vector3().crossVectors(e1, e2));
}

// A VRM (plan.vrm) is loaded with three-vrm's plugin: its materials (MToon) and spring bones; the page drives
// its raw bones itself (the plugin's normalized humanoid is not copied onto them).
export async function loadAvatar(bytes, plan) {
  const loader = new GLTFLoader();
  if (plan.vrm) {
    const { VRMLoaderPlugin } = await import('sm-vrm');
    loader.register(parser => new VRMLoaderPlugin(parser, { autoUpdateHumanBones: false }));
  }
  const gltf = await loader.parseAsync(bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.length), '');
  const vrm = gltf.userData.vrm || null;
  if (vrm) vrm.humanoid.autoUpdateHumanBones = false;
  const skins = [];
  gltf.scene.traverse(o => {
    if (o.isMesh) { o.castShadow = true; o.frustumCulled = false; }  // skinned: its bounds move with it
    if (o.isSkinnedMesh) skins.push(o);
  });
  const steps = plan.steps.map(s => ({ ...s, restDir: new THREE.Vector3(...s.rest_dir),
    restFrameT: m3(s.rest_frame).transpose(), restRotation: m3(s.rest_rotation),
    parentRest: m3(s.parent_rest_rotation) }));
  const nodes = await Promise.all(steps.map(s => gltf.parser.getDependency('node', s.node)));
  const hips = await gltf.parser.getDependency('node', plan.hips);
  const hipsInverse = m4(plan.hips_parent_inverse);
  const joint = (joints, j) => new THREE.Vector3(joints[3 * j], joints[3 * j + 1], joints[3 * j + 2]);
  const pose = { local: {}, hips: [0, 0, 0] };  // the last frame set (read back by the tests)
  const local = new THREE.Matrix4(), swing = new THREE.Quaternion(), carried = new THREE.Vector3();

  // One frame of joints (J * 3, metres, y-up): every driven bone's local rotation and the hips' position;
  // a VRM's spring bones, look-at and materials advance by the frame's time.
  let last = null;
  function drive(joints) {
    const deltas = [];
    steps.forEach((s, i) => {
      const P = s.ancestor >= 0 ? deltas[s.ancestor] : new THREE.Matrix4();
      const current = joint(joints, s.source[1]).sub(joint(joints, s.source[0]));
      let D;
      if (s.kind === 'swing') {
        carried.copy(s.restDir).applyMatrix4(P).normalize();
        swing.setFromUnitVectors(carried, current.normalize());
        D = new THREE.Matrix4().makeRotationFromQuaternion(swing).multiply(P);
      } else {
        const second = joint(joints, s.axis[0]).sub(joint(joints, s.axis[1]));
        D = frame(current, second).multiply(s.restFrameT);
      }
      deltas.push(D);
      local.copy(P).multiply(s.parentRest).transpose().multiply(D).multiply(s.restRotation);
      nodes[i].quaternion.setFromRotationMatrix(local);
      pose.local[s.node] = nodes[i].quaternion.toArray();
    });
    const path = joint(joints, plan.source_hips).multiplyScalar(plan.scale);
    path.y += plan.lift;
    hips.position.copy(path.applyMatrix4(hipsInverse));
    pose.hips = hips.position.toArray();
    if (vrm) {
      const now = performance.now();
      vrm.update(last === null ? 0 : Math.min((now - last) / 1000, 0.1));
      last = now;
    }
  }
  // Where the skins put every vertex now (world space, metres): one [x, y, z] list per skinned mesh.
  function vertices() {
    gltf.scene.updateMatrixWorld(true);
    const v = new THREE.Vector3();
    return skins.map(mesh => Array.from({ length: mesh.geometry.attributes.position.count },
                                        (_, k) => mesh.localToWorld(mesh.getVertexPosition(k, v)).toArray()));
  }
  return { scene: gltf.scene, drive, pose, vertices, vrm: !!vrm };
}
