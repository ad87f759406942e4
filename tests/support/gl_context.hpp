#pragma once
// A GLES 3.2 context on Mesa's llvmpipe (or any EGL device) through EGL surfaceless, for the
// tests that run shipped shaders. Compiled only where CMake found EGL and GLES (SPECBAKE_HAVE_GL).
#ifdef SPECBAKE_HAVE_GL
#include <EGL/egl.h>
#include <EGL/eglext.h>
#include <GLES3/gl32.h>

#include <string>
#include <vector>

namespace specbake::testing {

struct GlContext {
  EGLDisplay dpy = EGL_NO_DISPLAY;
  EGLContext ctx = EGL_NO_CONTEXT;
  std::string why;  // empty when current; else why there is no context (the test skips)
  GlContext() {
    auto get_display = reinterpret_cast<PFNEGLGETPLATFORMDISPLAYEXTPROC>(eglGetProcAddress("eglGetPlatformDisplayEXT"));
    if (!get_display) { why = "no eglGetPlatformDisplayEXT"; return; }
    dpy = get_display(EGL_PLATFORM_SURFACELESS_MESA, EGL_DEFAULT_DISPLAY, nullptr);
    if (dpy == EGL_NO_DISPLAY || !eglInitialize(dpy, nullptr, nullptr)) { why = "no surfaceless EGL display"; return; }
    if (!eglBindAPI(EGL_OPENGL_ES_API)) { why = "EGL cannot bind OpenGL ES"; return; }
    const EGLint attrs[] = {EGL_CONTEXT_MAJOR_VERSION, 3, EGL_CONTEXT_MINOR_VERSION, 2, EGL_NONE};
    ctx = eglCreateContext(dpy, EGL_NO_CONFIG_KHR, EGL_NO_CONTEXT, attrs);
    if (ctx == EGL_NO_CONTEXT) { why = "no GLES 3.2 context without a config"; return; }
    if (!eglMakeCurrent(dpy, EGL_NO_SURFACE, EGL_NO_SURFACE, ctx)) why = "cannot make the context current";
  }
  ~GlContext() {
    if (ctx != EGL_NO_CONTEXT) eglDestroyContext(dpy, ctx);
    if (dpy != EGL_NO_DISPLAY) eglTerminate(dpy);
  }
  GlContext(const GlContext&) = delete;
  GlContext& operator=(const GlContext&) = delete;
};

inline bool gl_has_extension(const char* name) {
  GLint n = 0;
  glGetIntegerv(GL_NUM_EXTENSIONS, &n);
  for (GLint i = 0; i < n; ++i)
    if (std::string(reinterpret_cast<const char*>(glGetStringi(GL_EXTENSIONS, i))) == name) return true;
  return false;
}

// A program from a vertex and a fragment shader; 0 with the compile/link log in `log` on failure.
inline GLuint gl_program(const std::string& vs, const std::string& fs, std::string& log) {
  const auto append_log = [&](auto get_log, GLuint object) {
    char buf[4096];
    get_log(object, sizeof buf, nullptr, buf);
    log += buf;
  };
  const auto compile = [&](GLenum type, const std::string& src) {
    const GLuint s = glCreateShader(type);
    const char* p = src.c_str();
    glShaderSource(s, 1, &p, nullptr);
    glCompileShader(s);
    GLint ok = 0;
    glGetShaderiv(s, GL_COMPILE_STATUS, &ok);
    if (!ok) append_log(glGetShaderInfoLog, s);
    return s;
  };
  const GLuint prog = glCreateProgram();
  glAttachShader(prog, compile(GL_VERTEX_SHADER, vs));
  glAttachShader(prog, compile(GL_FRAGMENT_SHADER, fs));
  glLinkProgram(prog);
  GLint linked = 0;
  glGetProgramiv(prog, GL_LINK_STATUS, &linked);
  if (linked) return prog;
  append_log(glGetProgramInfoLog, prog);
  return 0;
}

// An RGBA32F render target of w × h bound as the framebuffer, and the empty vertex array the
// full-screen triangle draws with. draw() runs the current program over every pixel and reads
// the floats back (row 0 at the bottom, 4 per pixel).
struct GlTarget {
  int width, height;
  GLuint texture = 0, fbo = 0, vao = 0;
  bool complete = false;
  GlTarget(int w, int h) : width(w), height(h) {
    // The texture is made on the active unit: leave that unit's binding as it was, so that a
    // target made after a test bound its textures does not replace one of them.
    GLint bound = 0;
    glGetIntegerv(GL_TEXTURE_BINDING_2D, &bound);
    glGenTextures(1, &texture);
    glBindTexture(GL_TEXTURE_2D, texture);
    glTexStorage2D(GL_TEXTURE_2D, 1, GL_RGBA32F, w, h);
    glBindTexture(GL_TEXTURE_2D, static_cast<GLuint>(bound));
    glGenFramebuffers(1, &fbo);
    glBindFramebuffer(GL_FRAMEBUFFER, fbo);
    glFramebufferTexture2D(GL_FRAMEBUFFER, GL_COLOR_ATTACHMENT0, GL_TEXTURE_2D, texture, 0);
    complete = glCheckFramebufferStatus(GL_FRAMEBUFFER) == GL_FRAMEBUFFER_COMPLETE;
    glGenVertexArrays(1, &vao);
  }
  std::vector<float> draw() const {
    glBindFramebuffer(GL_FRAMEBUFFER, fbo);
    glBindVertexArray(vao);
    glViewport(0, 0, width, height);
    glDrawArrays(GL_TRIANGLES, 0, 3);
    std::vector<float> px(4 * static_cast<std::size_t>(width) * height);
    glReadPixels(0, 0, width, height, GL_RGBA, GL_FLOAT, px.data());
    return px;
  }
};

// The opening of every GL test: a GLES 3.2 context named `gl` (the test skips, with the reason,
// where no EGL device opens one) with the float render targets and filtered float textures the
// tests draw and sample with.
#define SPECBAKE_GL_CONTEXT_OR_SKIP(gl)                                                                        \
  ::specbake::testing::GlContext gl;                                                                           \
  if (!gl.why.empty()) GTEST_SKIP() << "no EGL device: " << gl.why;                                            \
  ASSERT_TRUE(::specbake::testing::gl_has_extension("GL_EXT_color_buffer_float")) << "float render targets";   \
  ASSERT_TRUE(::specbake::testing::gl_has_extension("GL_OES_texture_float_linear")) << "filtered float textures"

// A full-screen triangle (no vertex buffers: gl_VertexID).
inline const char* kGlFullScreenVertex =
    "#version 320 es\nvoid main() {\n  vec2 c = vec2(gl_VertexID == 1 ? 3.0 : -1.0, gl_VertexID == 2 ? 3.0 : -1.0);\n"
    "  gl_Position = vec4(c, 0.0, 1.0);\n}\n";

}  // namespace specbake::testing
#endif
