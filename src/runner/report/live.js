// specbake report page: what the live views (sky.js, prism.js, lobes.js) share. A bundle's shipped
// GLSL (GLSL 4.50 / ES 3.20 text without #version) compiled as GLSL ES 3.00 for WebGL2 behind a
// full-screen triangle; views set up on every element of a class, a browser without what a view
// needs noted in the view (the static previews stay), any other failure a page error.
window.specbakeLive = (function () {
  'use strict';
  function Unavailable(message) { this.message = message; }
  var VERTEX = '#version 300 es\nvoid main() { vec2 p = vec2(float((gl_VertexID & 1) << 2) - 1.0, ' +
      'float((gl_VertexID & 2) << 1) - 1.0); gl_Position = vec4(p, 0.0, 1.0); }\n';
  return {
    Unavailable: Unavailable,
    SRGB: 'vec3 srgb(vec3 c) { return mix(12.92 * c, 1.055 * pow(c, vec3(1.0 / 2.4)) - 0.055, step(0.0031308, c)); }',
    context: function (canvas, what) {
      var gl = canvas.getContext('webgl2', {preserveDrawingBuffer: true});
      if (!gl) throw new Unavailable('no WebGL2 in this browser: the static previews above show ' + what);
      return gl;
    },
    // shipped: the bundle's text; samplers: the sampler types it uses; main: the view's own code.
    program: function (gl, name, shipped, samplers, main) {
      function compile(type, text) {
        var s = gl.createShader(type);
        gl.shaderSource(s, text);
        gl.compileShader(s);
        if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(name + ' as GLSL ES 3.00: ' + gl.getShaderInfoLog(s));
        return s;
      }
      var p = gl.createProgram();
      gl.attachShader(p, compile(gl.VERTEX_SHADER, VERTEX));
      gl.attachShader(p, compile(gl.FRAGMENT_SHADER, '#version 300 es\nprecision highp float;\nprecision highp int;\n' +
          samplers.map(function (s) { return 'precision highp ' + s + ';\n'; }).join('') + shipped + '\n' + main));
      gl.linkProgram(p);
      if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(name + ': link: ' + gl.getProgramInfoLog(p));
      gl.useProgram(p);
      return p;
    },
    // A float texture of `target` (TEXTURE_2D: dims [w, h]; TEXTURE_3D / TEXTURE_2D_ARRAY: [w, h, d])
    // on `unit`, filtered LINEAR (or NEAREST) and clamped to its edges on every axis.
    texture: function (gl, unit, target, internal, format, dims, values, filter) {
      gl.activeTexture(gl.TEXTURE0 + unit);
      var t = gl.createTexture(), f = filter || gl.LINEAR;
      gl.bindTexture(target, t);
      gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
      if (target === gl.TEXTURE_2D) gl.texImage2D(target, 0, internal, dims[0], dims[1], 0, format, gl.FLOAT, values);
      else gl.texImage3D(target, 0, internal, dims[0], dims[1], dims[2], 0, format, gl.FLOAT, values);
      gl.texParameteri(target, gl.TEXTURE_MIN_FILTER, f);
      gl.texParameteri(target, gl.TEXTURE_MAG_FILTER, f);
      gl.texParameteri(target, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
      gl.texParameteri(target, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
      if (target !== gl.TEXTURE_2D) gl.texParameteri(target, gl.TEXTURE_WRAP_R, gl.CLAMP_TO_EDGE);
      return t;
    },
    // Views that filter float32 textures need OES_texture_float_linear.
    needFloatFiltering: function (gl, what) {
      if (!gl.getExtension('OES_texture_float_linear'))
        throw new Unavailable('this WebGL2 cannot filter float32 textures (OES_texture_float_linear): the static ' +
                              'previews show ' + what);
    },
    // The canvas' RGBA bytes, row 0 at the bottom (the browser test reads them).
    pixels: function (gl, canvas) {
      var out = new Uint8Array(4 * canvas.width * canvas.height);
      gl.readPixels(0, 0, canvas.width, canvas.height, gl.RGBA, gl.UNSIGNED_BYTE, out);
      return Array.from(out);
    },
    // Redraws on every slider of the view.
    onInput: function (root, draw) {
      Array.prototype.forEach.call(root.querySelectorAll('input'), function (i) { i.addEventListener('input', draw); });
    },
    floats: function (b64) {
      var s = atob(b64), a = new Uint8Array(s.length);
      for (var i = 0; i < s.length; ++i) a[i] = s.charCodeAt(i);
      return new Float32Array(a.buffer);
    },
    // Sliders: their values by name, each shown in the <output> beside it.
    values: function (root) {
      var p = {};
      Array.prototype.forEach.call(root.querySelectorAll('input'), function (i) {
        p[i.name] = parseFloat(i.value);
        i.parentNode.querySelector('output').textContent = i.value;
      });
      return p;
    },
    // new View(root, data) on every element of `cls` (its data in script.live-data), kept in registry[job].
    mount: function (cls, View, registry) {
      Array.prototype.forEach.call(document.querySelectorAll('.' + cls), function (root) {
        var data = JSON.parse(root.querySelector('script.live-data').textContent);
        try {
          registry[data.job] = new View(root, data);
        } catch (e) {
          root.querySelector('canvas').hidden = true;
          root.querySelector('.live-status').textContent = e.message;
          if (e instanceof Unavailable) root.setAttribute('data-unavailable', e.message);
          else console.error(cls + ' of ' + data.job + ': ' + e.message);
        }
      });
    }
  };
})();
