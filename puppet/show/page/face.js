// The program feed: the face alone, drawn with WebGL 2 and the desktop renderer's own shaders,
// from the vertices the server streams (puppet/show/wire.py says the format). Nothing but the
// face is drawn: the page's background is transparent, for OBS's Browser Source.
"use strict";

const params = new URLSearchParams(location.search);
const token = params.get("token") || "";
const canvas = document.getElementById("face");
const note = document.getElementById("note");
const gl = canvas.getContext("webgl2", {alpha: true, premultipliedAlpha: true, preserveDrawingBuffer: true,
                                        antialias: params.get("antialias") !== "0"});
const KEY = 1, DELTA = 2, HEADER = 16;

// What the test and the delay measurement read: frames drawn, the newest frame's number.
window.facepuppet = {drawn: 0, number: 0, error: null};

function say(text) {
  note.textContent = text;
  if (text) window.facepuppet.error = text;
}

function fromBase64(text, Type) {
  const bytes = Uint8Array.from(atob(text), (c) => c.charCodeAt(0));
  return new Type(bytes.buffer);
}

function compile(kind, source) {
  const shader = gl.createShader(kind);
  gl.shaderSource(shader, source);
  gl.compileShader(shader);
  if (!gl.getShaderParameter(shader, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(shader));
  return shader;
}

// Where the lighting is computed: per pixel, or per vertex where WebGL runs on the CPU (SwiftShader,
// llvmpipe), as the desktop renderer chooses; ?shading=pixel|vertex says which.
function shading() {
  const asked = params.get("shading");
  if (asked === "pixel" || asked === "vertex") return asked;
  const info = gl.getExtension("WEBGL_debug_renderer_info");
  const renderer = info ? gl.getParameter(info.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER);
  return /swiftshader|llvmpipe|softpipe|software/i.test(renderer) ? "vertex" : "pixel";
}

function program(face) {
  const [vertexShader, fragmentShader] = face.shaders[shading()];
  const p = gl.createProgram();
  gl.attachShader(p, compile(gl.VERTEX_SHADER, vertexShader));
  gl.attachShader(p, compile(gl.FRAGMENT_SHADER, fragmentShader));
  gl.linkProgram(p);
  if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(p));
  return p;
}

// puppet.view.renderer.Camera's basis, view and projection, as one column-major matrix.
function viewProjection(camera, aspect) {
  const sub = (a, b) => a.map((v, i) => v - b[i]);
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const unit = (a) => { const n = Math.hypot(...a); return a.map((v) => v / n); };
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const back = unit(sub(camera.eye, camera.target));
  const right = unit(cross(camera.up, back));
  const up = cross(back, right);
  const rows = [right, up, back];
  const view = rows.map((r) => [...r, -dot(r, camera.eye)]).concat([[0, 0, 0, 1]]);
  const f = 1 / Math.tan((camera.fov * Math.PI) / 360);
  const [n, fa] = [camera.near, camera.far];
  const proj = [[f / aspect, 0, 0, 0], [0, f, 0, 0], [0, 0, (fa + n) / (n - fa), (2 * fa * n) / (n - fa)], [0, 0, -1, 0]];
  const out = new Float32Array(16);
  for (let r = 0; r < 4; r++) {
    for (let c = 0; c < 4; c++) {
      let sum = 0;
      for (let k = 0; k < 4; k++) sum += proj[r][k] * view[k][c];
      out[c * 4 + r] = sum;
    }
  }
  return out;
}

class Face {
  constructor(face) {
    this.face = face;
    this.n = face.n_vertices;
    this.triangles = fromBase64(face.triangles, Uint32Array);
    this.codes = new Uint16Array(this.n * 3);
    this.interleaved = new Float32Array(this.n * 6);  // position, normal
    this.normals = new Float32Array(this.n * 3);
    this.program = program(face);
    gl.useProgram(this.program);
    this.vao = gl.createVertexArray();
    gl.bindVertexArray(this.vao);
    this.dynamic = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, this.dynamic);
    gl.bufferData(gl.ARRAY_BUFFER, this.interleaved.byteLength, gl.DYNAMIC_DRAW);
    this.attribute("in_position", 3, 24, 0);
    this.attribute("in_normal", 3, 24, 12);
    this.buffer(fromBase64(face.materials, Float32Array));
    this.attribute("in_material", 4, 16, 0);
    if (face.textured) {
      this.buffer(fromBase64(face.surface, Float32Array));
      this.attribute("in_surface", 3, 12, 0);
      this.texture(face.texture_png);
    }
    const indices = gl.createBuffer();
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, indices);
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, this.triangles, gl.STATIC_DRAW);
    for (const [name, value] of Object.entries(face.uniforms)) {
      gl.uniform3fv(gl.getUniformLocation(this.program, name), value);
    }
    gl.uniform3fv(gl.getUniformLocation(this.program, "eye"), face.camera.eye);
    gl.uniform3fv(gl.getUniformLocation(this.program, "light_direction"), face.light_direction);
    this.viewProjection = gl.getUniformLocation(this.program, "view_projection");
    this.ready = !face.textured;
  }

  buffer(data) {
    gl.bindBuffer(gl.ARRAY_BUFFER, gl.createBuffer());
    gl.bufferData(gl.ARRAY_BUFFER, data, gl.STATIC_DRAW);
  }

  attribute(name, size, stride, offset) {
    const location = gl.getAttribLocation(this.program, name);
    if (location < 0) return;  // a variant that does not use it
    gl.enableVertexAttribArray(location);
    gl.vertexAttribPointer(location, size, gl.FLOAT, false, stride, offset);
  }

  texture(png) {
    const image = new Image();
    image.onload = () => {
      gl.useProgram(this.program);
      gl.activeTexture(gl.TEXTURE0);
      gl.bindTexture(gl.TEXTURE_2D, gl.createTexture());
      gl.pixelStorei(gl.UNPACK_FLIP_Y_WEBGL, true);  // rows bottom first, as the desktop uploads them
      gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGB, gl.RGB, gl.UNSIGNED_BYTE, image);
      gl.generateMipmap(gl.TEXTURE_2D);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.LINEAR_MIPMAP_LINEAR);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
      gl.uniform1i(gl.getUniformLocation(this.program, "albedo_map"), 0);
      this.ready = true;
    };
    image.src = "data:image/png;base64," + png;
  }

  // A frame's u16 codes (a whole frame, or the difference from the one before) into positions
  // and area-weighted unit normals, as puppet.runtime.normals.VertexNormals sums them.
  update(kind, codes) {
    if (kind === KEY) this.codes.set(codes);
    else for (let i = 0; i < codes.length; i++) this.codes[i] = (this.codes[i] + codes[i]) & 0xffff;
    const {origin, step} = this.face;
    const p = this.interleaved, nrm = this.normals, t = this.triangles;
    for (let k = 0; k < 3; k++) {  // the codes come a coordinate at a time: every x, every y, every z
      for (let v = 0; v < this.n; v++) p[v * 6 + k] = origin[k] + this.codes[k * this.n + v] * step[k];
    }
    nrm.fill(0);
    for (let i = 0; i < t.length; i += 3) {
      const a = t[i] * 6, b = t[i + 1] * 6, c = t[i + 2] * 6;
      const ux = p[b] - p[a], uy = p[b + 1] - p[a + 1], uz = p[b + 2] - p[a + 2];
      const vx = p[c] - p[a], vy = p[c + 1] - p[a + 1], vz = p[c + 2] - p[a + 2];
      const nx = uy * vz - uz * vy, ny = uz * vx - ux * vz, nz = ux * vy - uy * vx;
      for (const j of [t[i], t[i + 1], t[i + 2]]) {
        nrm[j * 3] += nx; nrm[j * 3 + 1] += ny; nrm[j * 3 + 2] += nz;
      }
    }
    for (let v = 0; v < this.n; v++) {
      const x = nrm[v * 3], y = nrm[v * 3 + 1], z = nrm[v * 3 + 2];
      const length = Math.hypot(x, y, z) || 1;
      p[v * 6 + 3] = x / length; p[v * 6 + 4] = y / length; p[v * 6 + 5] = z / length;
    }
    this.dirty = true;
  }

  draw() {
    const width = canvas.clientWidth * devicePixelRatio | 0, height = canvas.clientHeight * devicePixelRatio | 0;
    if (canvas.width !== width || canvas.height !== height) [canvas.width, canvas.height] = [width, height];
    gl.viewport(0, 0, width, height);
    gl.clearColor(0, 0, 0, 0);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.enable(gl.DEPTH_TEST);
    gl.enable(gl.CULL_FACE);
    gl.useProgram(this.program);
    gl.bindVertexArray(this.vao);
    gl.uniformMatrix4fv(this.viewProjection, false, viewProjection(this.face.camera, width / height));
    gl.bindBuffer(gl.ARRAY_BUFFER, this.dynamic);
    gl.bufferSubData(gl.ARRAY_BUFFER, 0, this.interleaved);
    gl.drawElements(gl.TRIANGLES, this.triangles.length, gl.UNSIGNED_INT, 0);
    this.dirty = false;
  }
}

async function inflate(bytes) {
  const stream = new Blob([bytes]).stream().pipeThrough(new DecompressionStream("deflate"));
  return new Uint16Array(await new Response(stream).arrayBuffer());
}

function connect() {
  const socket = new WebSocket(`ws://${location.host}/feed?token=${encodeURIComponent(token)}`);
  socket.binaryType = "arraybuffer";
  let face = null, decoding = Promise.resolve(), shown = null;
  socket.onmessage = (event) => {
    if (typeof event.data === "string") {
      face = new Face(JSON.parse(event.data));
      return;
    }
    const header = new DataView(event.data, 0, HEADER);
    const kind = header.getUint8(0), number = header.getUint32(4, true), published = header.getFloat64(8, true);
    const body = new Uint8Array(event.data, HEADER);
    decoding = decoding.then(async () => {  // in order: a delta needs the frame before it
      face.update(kind, await inflate(body));
      shown = {number, published};
    });
  };
  function frame() {
    if (face && face.ready && face.dirty && shown) {
      face.draw();
      window.facepuppet.drawn += 1;
      window.facepuppet.number = shown.number;
      if (socket.readyState === WebSocket.OPEN) socket.send(JSON.stringify({drawn: shown.number, published: shown.published}));
    }
    requestAnimationFrame(frame);
  }
  requestAnimationFrame(frame);
  socket.onclose = () => {
    say("feed closed: reconnecting");
    setTimeout(connect, 1000);
  };
  socket.onopen = () => say("");
}

if (!gl) say("this browser has no WebGL 2");
else connect();
