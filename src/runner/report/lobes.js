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
    if (!gl.getExtension('OES_texture_float_linear'))
      throw new L.Unavailable('this WebGL2 cannot filter float32 textures (OES_texture_float_linear): the static previews show the lobes');
    var program = L.program(gl, 'diffraction_brdf.glsl', data.glsl, ['sampler2DArray'], MAIN);
    var t = data.textures.table_terms, s = t.shape;  // [terms][iv][iu][re, im]
    gl.activeTexture(gl.TEXTURE0);
    gl.bindTexture(gl.TEXTURE_2D_ARRAY, gl.createTexture());
    gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
    gl.texImage3D(gl.TEXTURE_2D_ARRAY, 0, gl.RG32F, s[2], s[1], s[0], 0, gl.RG, gl.FLOAT, L.floats(t.base64));
    gl.texParameteri(gl.TEXTURE_2D_ARRAY, gl.TEXTURE_MIN_FILTER, gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_2D_ARRAY, gl.TEXTURE_MAG_FILTER, gl.LINEAR);
    gl.texParameteri(gl.TEXTURE_2D_ARRAY, gl.TEXTURE_WRAP_S, gl.CLAMP_TO_EDGE);
    gl.texParameteri(gl.TEXTURE_2D_ARRAY, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
    gl.uniform1i(gl.getUniformLocation(program, 'terms'), 0);
    function draw() {
      var p = L.values(root), a = p.light_angle_deg * Math.PI / 180;
      gl.uniform3f(gl.getUniformLocation(program, 'wi'), -Math.sin(a), 0, Math.cos(a));
      gl.uniform1f(gl.getUniformLocation(program, 'scale'), Math.pow(2, p.exposure));
      gl.uniform2f(gl.getUniformLocation(program, 'size'), canvas.width, canvas.height);
      gl.viewport(0, 0, canvas.width, canvas.height);
      gl.drawArrays(gl.TRIANGLES, 0, 3);
    }
    Array.prototype.forEach.call(root.querySelectorAll('input'), function (i) { i.addEventListener('input', draw); });
    draw();
    root.querySelector('.live-status').textContent = s[0] + ' terms, table ' + s[2] + ' x ' + s[1] +
        '; WebGL2: ' + (gl.getParameter(gl.VERSION) || '');
    this.pixels = function () {
      var out = new Uint8Array(4 * canvas.width * canvas.height);
      gl.readPixels(0, 0, canvas.width, canvas.height, gl.RGBA, gl.UNSIGNED_BYTE, out);
      return Array.from(out);
    };
  }

  L.mount('live-lobes', Lobes, window.specbakeLobes);
})();
