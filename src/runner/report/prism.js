// specbake report page: the live prism of a dispersion bundle. Its own dispersion.glsl compiled as
// GLSL ES 3.00 in WebGL2: the per-sample renders of a white beam one unit wide (sample n lands at
// spread * SPECBAKE_IOR_OFFSET[n]; each pixel holds the beam's coverage of it) in an RGBA32F 2D
// array texture, one layer per sample, summed per pixel by specbake_dispersion_combine.
// window.specbakePrism[job].pixels() returns the canvas' RGBA bytes (row 0 at the bottom).
(function () {
  'use strict';
  var L = window.specbakeLive;
  window.specbakePrism = {};

  var MAIN = [
    'uniform highp sampler2DArray renders;',
    'out vec4 color;',
    L.SRGB,
    'void main() {',
    '  vec3 c = specbake_dispersion_combine(renders, ivec2(int(gl_FragCoord.x), 0));',
    '  color = vec4(srgb(clamp(c, 0.0, 1.0)), 1.0);',
    '}'].join('\n');

  // The array constant SPECBAKE_IOR_OFFSET of the shipped text, as numbers.
  function offsets(glsl) {
    var m = /SPECBAKE_IOR_OFFSET\[\d+\]\s*=\s*float\[\d+\]\(([^)]*)\)/.exec(glsl);
    if (!m) throw new Error('dispersion.glsl has no SPECBAKE_IOR_OFFSET array');
    return m[1].split(',').map(parseFloat);
  }

  function Prism(root, data) {
    var canvas = root.querySelector('canvas');
    var gl = L.context(canvas, 'the prism');
    var program = L.program(gl, 'dispersion.glsl', data.glsl, ['sampler2DArray'], MAIN);
    var off = offsets(data.glsl), n = off.length, w = canvas.width;
    var lo = Math.min.apply(null, off), hi = Math.max.apply(null, off);
    var tex = gl.createTexture();
    gl.activeTexture(gl.TEXTURE0);
    gl.bindTexture(gl.TEXTURE_2D_ARRAY, tex);
    gl.texParameteri(gl.TEXTURE_2D_ARRAY, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
    gl.texParameteri(gl.TEXTURE_2D_ARRAY, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
    gl.uniform1i(gl.getUniformLocation(program, 'renders'), 0);
    var input = root.querySelector('input');

    function draw() {
      var spread = L.values(root).spread;
      // the strip spans the landing points of the widest spread the control offers, so that a
      // larger spread spreads the colours wider on the page
      var smax = parseFloat(input.max), x0 = smax * lo - 0.5, dx = (smax * (hi - lo) + 1) / w;
      var px = new Float32Array(4 * w * n);
      for (var s = 0; s < n; ++s) {
        var a = spread * off[s] - 0.5, b = a + 1;
        for (var x = 0; x < w; ++x) {
          var l = x0 + dx * x, cover = Math.max(0, Math.min(b, l + dx) - Math.max(a, l)) / dx, i = 4 * (s * w + x);
          px[i] = px[i + 1] = px[i + 2] = cover;
          px[i + 3] = 1;
        }
      }
      gl.texImage3D(gl.TEXTURE_2D_ARRAY, 0, gl.RGBA32F, w, 1, n, 0, gl.RGBA, gl.FLOAT, px);
      gl.viewport(0, 0, w, canvas.height);
      gl.drawArrays(gl.TRIANGLES, 0, 3);
    }
    input.addEventListener('input', draw);
    draw();
    root.querySelector('.live-status').textContent = n + ' samples; WebGL2: ' + (gl.getParameter(gl.VERSION) || '');
    this.pixels = function () { return L.pixels(gl, canvas); };
  }

  L.mount('live-prism', Prism, window.specbakePrism);
})();
