// specbake report page: the live BRDF lobes of a diffraction table bundle. Its own
// shader/diffraction_brdf.glsl compiled as GLSL ES 3.00 in WebGL2 on its table (table_terms.bin:
// an RG32F 2D array texture, one layer per term, LINEAR, CLAMP_TO_EDGE, as the shader's header
// asks): diffraction_srgb_fast over the outgoing hemisphere seen from above (orthographic: pixel
// (x, y) in the unit disc looks along wo = (x, y, sqrt(1 - x^2 - y^2))), the light at a polar
// angle in the x-z plane, on the -x side (the mirror direction on the right).
(function () {
  'use strict';
  var L = window.specbakeLive;
  window.specbakeLobes = {};
  var MAIN = [
    'uniform highp sampler2DArray terms;',
    'uniform vec3 wi;',
    'uniform float scale;',
    'uniform vec2 size;',
    'out vec4 color;',
    L.SRGB,
    'void main() {',
    '  vec2 p = 2.0 * gl_FragCoord.xy / size - 1.0;',
    '  float r2 = dot(p, p);',
    '  if (r2 >= 1.0) { color = vec4(0.0, 0.0, 0.0, 1.0); return; }',
    '  vec3 c = diffraction_srgb_fast(terms, wi, vec3(p, sqrt(1.0 - r2)));',
    '  color = vec4(srgb(clamp(c * scale, 0.0, 1.0)), 1.0);',
    '}'].join('\n');

  function Lobes(root, data) {
    var canvas = root.querySelector('canvas');
    var gl = L.context(canvas, 'the lobes');
    L.needFloatFiltering(gl, 'the lobes');
    var program = L.program(gl, 'diffraction_brdf.glsl', data.glsl, ['sampler2DArray'], MAIN);
    var t = data.textures.table_terms, s = t.shape;  // [terms][iv][iu][re, im]
    L.texture(gl, 0, gl.TEXTURE_2D_ARRAY, gl.RG32F, gl.RG, [s[2], s[1], s[0]], L.floats(t.base64));
    gl.uniform1i(gl.getUniformLocation(program, 'terms'), 0);
    function draw() {
      var p = L.values(root), a = p.light_angle_deg * Math.PI / 180;
      gl.uniform3f(gl.getUniformLocation(program, 'wi'), -Math.sin(a), 0, Math.cos(a));
      gl.uniform1f(gl.getUniformLocation(program, 'scale'), Math.pow(2, p.exposure));
      gl.uniform2f(gl.getUniformLocation(program, 'size'), canvas.width, canvas.height);
      gl.viewport(0, 0, canvas.width, canvas.height);
      gl.drawArrays(gl.TRIANGLES, 0, 3);
    }
    L.onInput(root, draw);
    draw();
    root.querySelector('.live-status').textContent = s[0] + ' terms, table ' + s[2] + ' x ' + s[1] +
        '; WebGL2: ' + (gl.getParameter(gl.VERSION) || '');
    this.pixels = function () { return L.pixels(gl, canvas); };
  }

  L.mount('live-lobes', Lobes, window.specbakeLobes);
})();
