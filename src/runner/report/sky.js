// specbake report page: the live sky of an atmosphere bundle. Its own sampling.glsl (GLSL 4.50 /
// ES 3.20 text without #version) compiled as GLSL ES 3.00 in WebGL2, on its float32 textures
// (transmittance 2D, scattering and single Mie 3D, the sky-view table's two 3D textures where the
// bundle has them; LINEAR, CLAMP_TO_EDGE, as sampling.glsl's header asks), GetSkyRadiance (or
// GetSkyRadianceWithSkyView) per pixel of an equidistant fisheye. Where WebGL2 or linear
// filtering of float textures is missing, the page says so and keeps the static previews.
// window.specbakeSky[job].radiance({sun_elevation_deg, sun_azimuth_deg, altitude_km}, n) renders
// n x n pixels of linear radiance into a float framebuffer and returns them (the browser test
// compares them with the host's double evaluation).
(function () {
  'use strict';
  var L = window.specbakeLive;
  window.specbakeSky = {};

  // Equidistant fisheye (render.cpp's fisheye_direction): pixel centre (x, y) in (-1, 1), row 0 at
  // the bottom; w = 1 inside the circle, 0 outside.
  function directions(n) {
    var d = new Float32Array(4 * n * n);
    for (var y = 0; y < n; ++y) {
      for (var x = 0; x < n; ++x) {
        var dx = (2 * x + 1) / n - 1, dy = (2 * y + 1) / n - 1, rho = Math.sqrt(dx * dx + dy * dy), i = 4 * (y * n + x);
        if (rho > 1) continue;
        var theta = rho * Math.PI / 2, phi = Math.atan2(dy, dx);
        d[i] = Math.sin(theta) * Math.cos(phi);
        d[i + 1] = Math.sin(theta) * Math.sin(phi);
        d[i + 2] = Math.cos(theta);
        d[i + 3] = 1;
      }
    }
    return d;
  }

  function sunDirection(p) {
    var e = p.sun_elevation_deg * Math.PI / 180, a = p.sun_azimuth_deg * Math.PI / 180;
    return new Float32Array([Math.cos(e) * Math.cos(a), Math.cos(e) * Math.sin(a), Math.sin(e)]);
  }

  // The fragment shader: GetSkyRadiance, or with a sky-view table (bundles of scenes whose sun
  // sets) GetSkyRadianceWithSkyView, which reads the table where it holds the camera and the sun.
  function main(table) {
    return [
      'uniform highp sampler2D transmittance_texture;',
      'uniform highp sampler3D scattering_texture;',
      'uniform highp sampler3D single_mie_scattering_texture;',
      table ? 'uniform highp sampler3D sky_view_texture;\nuniform highp sampler3D sky_view_mie_texture;' : '',
      'uniform highp sampler2D directions;',
      'uniform vec3 sun;',
      'uniform float altitude_km;',
      'uniform float scale;',
      'uniform int linear_out;',
      'out vec4 color;',
      L.SRGB,
      'void main() {',
      '  vec4 d = texelFetch(directions, ivec2(gl_FragCoord.xy), 0);',
      '  if (d.w == 0.0) { color = vec4(0.0); return; }',
      '  vec3 t;',
      table
        ? '  vec3 l = GetSkyRadianceWithSkyView(SPECBAKE_ATMOSPHERE, SPECBAKE_SKY_VIEW, transmittance_texture,\n' +
          '      scattering_texture, single_mie_scattering_texture, sky_view_texture, sky_view_mie_texture,\n' +
          '      vec3(0.0, 0.0, 1.0), altitude_km, d.xyz, sun, t);'
        : '  vec3 l = GetSkyRadiance(SPECBAKE_ATMOSPHERE, transmittance_texture, scattering_texture,\n' +
          '      single_mie_scattering_texture, vec3(0.0, 0.0, 1.0), altitude_km, d.xyz, 0.0, sun, t);',
      '  color = linear_out == 1 ? vec4(l, 1.0) : vec4(srgb(1.0 - exp(-max(l, 0.0) * scale)), 1.0);',
      '}'].join('\n');
  }

  function Sky(root, data) {
    var canvas = root.querySelector('canvas'), status = root.querySelector('.live-status');
    var gl = L.context(canvas, 'the sky');
    L.needFloatFiltering(gl, 'the sky');
    var floatTarget = gl.getExtension('EXT_color_buffer_float');

    var table = !!data.textures.sky_view;
    var program = L.program(gl, 'sampling.glsl', data.glsl, ['sampler2D', 'sampler3D'], main(table));

    // shapes as the .bin files have them, RGB last: [rows][cols][3] (2D), [depth][rows][cols][3]
    // (3D), the sky-view table [sun][altitude][view][azimuth][3] (3D: azimuth, view, sun·altitude)
    function texture(unit, target, tex) {
      var s = tex.shape, dims = s.length === 3 ? [s[1], s[0]] : s.length === 4 ? [s[2], s[1], s[0]]
                                                                          : [s[3], s[2], s[0] * s[1]];
      L.texture(gl, unit, target, gl.RGB32F, gl.RGB, dims, L.floats(tex.base64));
    }
    texture(0, gl.TEXTURE_2D, data.textures.transmittance);
    texture(1, gl.TEXTURE_3D, data.textures.scattering);
    texture(2, gl.TEXTURE_3D, data.textures.single_mie_scattering);
    gl.uniform1i(gl.getUniformLocation(program, 'transmittance_texture'), 0);
    gl.uniform1i(gl.getUniformLocation(program, 'scattering_texture'), 1);
    gl.uniform1i(gl.getUniformLocation(program, 'single_mie_scattering_texture'), 2);
    gl.uniform1i(gl.getUniformLocation(program, 'directions'), 3);
    if (table) {
      texture(4, gl.TEXTURE_3D, data.textures.sky_view);
      texture(5, gl.TEXTURE_3D, data.textures.sky_view_single_mie);
      gl.uniform1i(gl.getUniformLocation(program, 'sky_view_texture'), 4);
      gl.uniform1i(gl.getUniformLocation(program, 'sky_view_mie_texture'), 5);
    }
    var dirTex = null, dirSize = 0;
    function useDirections(n) {
      if (n === dirSize) return;
      if (dirTex) gl.deleteTexture(dirTex);
      dirTex = L.texture(gl, 3, gl.TEXTURE_2D, gl.RGBA32F, gl.RGBA, [n, n], directions(n), gl.NEAREST);
      dirSize = n;
    }
    function draw(p, n, linear) {
      var sun = sunDirection(p);
      useDirections(n);
      gl.uniform3fv(gl.getUniformLocation(program, 'sun'), sun);
      gl.uniform1f(gl.getUniformLocation(program, 'altitude_km'), p.altitude_km);
      gl.uniform1f(gl.getUniformLocation(program, 'scale'), Math.pow(2, p.exposure || 0));
      gl.uniform1i(gl.getUniformLocation(program, 'linear_out'), linear ? 1 : 0);
      gl.viewport(0, 0, n, n);
      gl.drawArrays(gl.TRIANGLES, 0, 3);
      return {sun: Array.from(sun), altitude_km: Math.fround(p.altitude_km)};
    }

    function redraw() {
      gl.bindFramebuffer(gl.FRAMEBUFFER, null);
      draw(L.values(root), canvas.width, false);
    }
    L.onInput(root, redraw);
    redraw();
    status.textContent = 'WebGL2: ' + (gl.getParameter(gl.VERSION) || '') + '; rendering live';

    // Linear radiance of an n x n view, row 0 at the bottom, RGBA per pixel.
    this.radiance = function (p, n) {
      if (!floatTarget) throw new Error('no EXT_color_buffer_float: cannot read radiance back');
      var fb = gl.createFramebuffer(), rb = gl.createRenderbuffer();
      gl.bindRenderbuffer(gl.RENDERBUFFER, rb);
      gl.renderbufferStorage(gl.RENDERBUFFER, gl.RGBA32F, n, n);
      gl.bindFramebuffer(gl.FRAMEBUFFER, fb);
      gl.framebufferRenderbuffer(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.RENDERBUFFER, rb);
      var inputsUsed = draw(p, n, true), px = new Float32Array(4 * n * n);
      gl.readPixels(0, 0, n, n, gl.RGBA, gl.FLOAT, px);
      gl.bindFramebuffer(gl.FRAMEBUFFER, null);
      gl.deleteFramebuffer(fb);
      gl.deleteRenderbuffer(rb);
      redraw();
      inputsUsed.n = n;
      inputsUsed.rgba = Array.from(px);
      inputsUsed.renderer = gl.getParameter(gl.RENDERER);
      return inputsUsed;
    };
  }

  L.mount('live-sky', Sky, window.specbakeSky);
})();
