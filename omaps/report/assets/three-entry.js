export {
  WebGLRenderer, Scene, PerspectiveCamera, Color, BufferGeometry, BufferAttribute, Float32BufferAttribute,
  InstancedMesh, Mesh, ShaderMaterial, MeshLambertMaterial, DoubleSide, Matrix4, Vector3, Box3, Sphere,
  Texture, DataTexture, NearestFilter, LinearFilter, RepeatWrapping, ClampToEdgeWrapping, RGBAFormat,
  UnsignedByteType, HemisphereLight, DirectionalLight, AmbientLight, SRGBColorSpace, NoColorSpace, GLSL3
} from 'three';
export { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';
