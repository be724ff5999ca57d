// Mesh files for the inputs A and B and the outputs (DESIGN.md, stages "load" and "outputs"): OBJ with per-corner
// UVs and an MTL texture, OFF, and PLY (ASCII and binary little-endian).
//
// OBJ geometry is parsed here rather than by tinyobjloader: its number parser is not correctly rounded (written
// files would not read back bit-exactly), it turns "nan" or garbage into 0 without a word, the linked build stores
// float, and its triangulation is not a plain fan. tinyobjloader still parses the MTL (texture options and all).
#include "io/mesh_io.h"

#include <tiny_obj_loader.h>

#include <algorithm>
#include <cctype>
#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <vector>

#include "mesh/errors.h"

#if !defined(__BYTE_ORDER__) || __BYTE_ORDER__ != __ORDER_LITTLE_ENDIAN__
#error "binary PLY reading and writing assume a little-endian host"
#endif

namespace fs = std::filesystem;

namespace morphmap {

namespace {

// ---------------------------------------------------------------------------------------------------------------
// Shared helpers

std::string read_whole_file(const std::string& path) {
  std::error_code ec;
  if (fs::is_directory(path, ec)) throw IoError(path + ": is a directory, not a mesh file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw IoError(path + ": cannot open file");
  std::string data;
  in.seekg(0, std::ios::end);
  const std::streamoff size = in.tellg();
  if (size < 0) throw IoError(path + ": cannot read file");
  data.resize(static_cast<std::size_t>(size));
  in.seekg(0, std::ios::beg);
  if (size > 0 && !in.read(data.data(), size)) throw IoError(path + ": cannot read file");
  return data;
}

std::string lower(std::string s) {
  for (char& c : s) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return s;
}

// Polygons as read from a file, before fan triangulation.
struct Polygons {
  std::vector<long long> corners;      // vertex index of every corner, 0-based (may still be out of range)
  std::vector<long long> corner_uvs;   // texture index of every corner, when every corner has one
  std::vector<std::size_t> starts{0};  // polygon p has corners [starts[p], starts[p + 1])
  std::vector<int> lines;              // source line of every polygon (text formats), for messages
  std::size_t count() const { return starts.size() - 1; }
};

Eigen::MatrixXi fan_triangulate(const Polygons& polygons, const std::vector<long long>& corner_values) {
  std::size_t triangles = 0;
  for (std::size_t p = 0; p < polygons.count(); ++p) triangles += polygons.starts[p + 1] - polygons.starts[p] - 2;
  Eigen::MatrixXi F(static_cast<Eigen::Index>(triangles), 3);
  Eigen::Index row = 0;
  for (std::size_t p = 0; p < polygons.count(); ++p) {
    const std::size_t s = polygons.starts[p];
    for (std::size_t k = s + 1; k + 1 < polygons.starts[p + 1]; ++k) {
      F(row, 0) = static_cast<int>(corner_values[s]);
      F(row, 1) = static_cast<int>(corner_values[k]);
      F(row, 2) = static_cast<int>(corner_values[k + 1]);
      ++row;
    }
  }
  return F;
}

Eigen::MatrixXd to_matrix(const std::vector<double>& flat, int columns) {
  Eigen::MatrixXd M(static_cast<Eigen::Index>(flat.size() / columns), columns);
  for (Eigen::Index i = 0; i < M.rows(); ++i) {
    for (int c = 0; c < columns; ++c) M(i, c) = flat[static_cast<std::size_t>(i) * columns + c];
  }
  return M;
}

// std::from_chars of the whole of [begin, end): correctly rounded like strtod and a few times faster (half of
// horse.obj's 36 ms read was strtod and strtoll). False where it stops early ('+', hexadecimal, out of range): the
// callers then read the text with strtod / strtoll, so every text reads as those read it.
template <class T>
bool whole_from_chars(const char* begin, const char* end, T& value) {
  const auto [ptr, ec] = std::from_chars(begin, end, value);
  return ec == std::errc() && ptr == end;
}

// The one text-line reader of OBJ and OFF. `line` must be NUL-terminated (the file buffer's newlines are
// replaced by NULs), so strtod cannot run into the next line.
class LineCursor {
 public:
  LineCursor(const std::string& path, int line_number, const char* line)
      : path_(&path), line_number_(line_number), p_(line) {}

  [[noreturn]] void fail(const std::string& problem) const {
    throw InvalidInput(*path_ + ": line " + std::to_string(line_number_) + ": " + problem);
  }

  /// True when only blanks or a comment are left.
  bool at_end() {
    skip_blanks();
    return *p_ == '\0' || *p_ == '#';
  }

  /// The next blank-separated token ("" at the end of the line).
  std::string word() {
    if (at_end()) return {};
    const char* start = p_;
    while (!is_delimiter(*p_)) ++p_;
    return std::string(start, p_);
  }

  /// The rest of the line without surrounding blanks (file names may contain spaces).
  std::string rest() {
    skip_blanks();
    std::string s(p_);
    p_ += s.size();
    while (!s.empty() && std::isspace(static_cast<unsigned char>(s.back()))) s.pop_back();
    return s;
  }

  bool number(double& value) {
    if (at_end()) return false;
    if (const char* stop = token_end(); whole_from_chars(p_, stop, value)) {
      p_ = stop;
      return true;
    }
    char* end = nullptr;
    value = std::strtod(p_, &end);
    if (end == p_ || !is_delimiter(*end)) fail("bad number '" + word() + "'");
    p_ = end;
    return true;
  }

  bool integer(long long& value) {
    if (at_end()) return false;
    if (const char* stop = token_end(); whole_from_chars(p_, stop, value)) {
      p_ = stop;
      return true;
    }
    char* end = nullptr;
    errno = 0;
    value = std::strtoll(p_, &end, 10);
    if (end == p_ || !is_delimiter(*end) || errno == ERANGE) fail("bad integer '" + word() + "'");
    p_ = end;
    return true;
  }

 private:
  static bool is_delimiter(char c) { return c == '\0' || c == ' ' || c == '\t' || c == '#'; }
  const char* token_end() const {
    const char* end = p_;
    while (!is_delimiter(*end)) ++end;
    return end;
  }
  void skip_blanks() {
    while (*p_ == ' ' || *p_ == '\t') ++p_;
  }

  const std::string* path_;
  int line_number_;
  const char* p_;
};

// Splits `data` into NUL-terminated lines in place; carriage returns become blanks. Searched with memchr, which scans
// many bytes a step (a byte-by-byte loop was a tenth of reading horse.obj).
std::vector<const char*> split_lines(std::string& data) {
  std::vector<const char*> lines;
  char* const d = data.data();
  const std::size_t n = data.size();
  for (std::size_t start = 0; start < n;) {
    const void* newline = std::memchr(d + start, '\n', n - start);
    std::size_t end = newline != nullptr ? std::size_t(static_cast<const char*>(newline) - d) : n;
    const void* nul = std::memchr(d + start, '\0', end - start);  // a NUL ends a line too
    if (nul != nullptr) end = std::size_t(static_cast<const char*>(nul) - d);
    for (char* r = d + start; (r = static_cast<char*>(std::memchr(r, '\r', std::size_t(d + end - r)))) != nullptr;)
      *r++ = ' ';
    lines.push_back(d + start);
    if (end < n) d[end] = '\0';  // past the last byte, data.c_str() ends with a NUL already
    start = end + 1;
  }
  return lines;
}

// ---------------------------------------------------------------------------------------------------------------
// OBJ

// Splits an OBJ face corner "v", "v/vt", "v//vn" or "v/vt/vn" into its vertex and texture indices (0 = absent).
void parse_obj_corner(const LineCursor& cursor, const std::string& token, long long& v, long long& vt) {
  // strtoll where from_chars stops early (it also takes '+5'), with its errors.
  auto parse_index = [&](const char* begin, const char* end) -> long long {
    if (begin == end) return 0;
    long long value = 0;
    if (!whole_from_chars(begin, end, value)) {
      const std::string text(begin, end);
      char* stop = nullptr;
      errno = 0;
      value = std::strtoll(text.c_str(), &stop, 10);
      if (stop != text.c_str() + text.size() || errno == ERANGE) cursor.fail("bad face corner '" + token + "'");
    }
    if (value == 0) cursor.fail("face corner '" + token + "' has index 0 (OBJ indices start at 1)");
    return value;
  };
  const char* const text = token.c_str();
  const char* const text_end = text + token.size();
  const std::size_t slash = token.find('/');
  v = parse_index(text, slash == std::string::npos ? text_end : text + slash);
  if (v == 0) cursor.fail("face corner '" + token + "' has no vertex index");
  vt = 0;
  if (slash == std::string::npos) return;
  const std::size_t slash2 = token.find('/', slash + 1);
  vt = parse_index(text + slash + 1, slash2 == std::string::npos ? text_end : text + slash2);
}

// Loads the materials of every library (missing libraries are skipped: an OBJ without its MTL is still a mesh).
std::map<std::string, std::string> load_material_textures(const fs::path& folder,
                                                          const std::vector<std::string>& libraries,
                                                          std::string& first_texture) {
  std::map<std::string, std::string> textures;
  for (const std::string& library : libraries) {
    std::ifstream in(folder / library);
    if (!in) continue;
    std::map<std::string, int> material_map;
    std::vector<tinyobj::material_t> materials;
    std::string warning, error;
    tinyobj::LoadMtl(&material_map, &materials, &in, &warning, &error);
    for (const tinyobj::material_t& m : materials) {
      if (m.diffuse_texname.empty()) continue;
      textures.emplace(m.name, m.diffuse_texname);
      if (first_texture.empty()) first_texture = m.diffuse_texname;
    }
  }
  return textures;
}

std::string resolve_texture(const fs::path& folder, std::string name) {
  std::replace(name.begin(), name.end(), '\\', '/');  // files written on Windows
  fs::path texture(name);
  if (texture.is_relative()) texture = folder / texture;
  std::error_code ec;
  if (!fs::is_regular_file(texture, ec)) return {};
  return texture.lexically_normal().string();
}

Surface read_obj(const std::string& path) {
  std::string data = read_whole_file(path);
  const std::vector<const char*> lines = split_lines(data);
  std::vector<double> positions, uvs;
  Polygons polygons;
  bool all_corners_have_uv = true;
  std::vector<std::string> libraries;
  std::vector<std::string> used_materials;  // in the order faces use them
  std::string current_material;

  for (std::size_t l = 0; l < lines.size(); ++l) {
    LineCursor cursor(path, static_cast<int>(l + 1), lines[l]);
    const std::string keyword = cursor.word();
    if (keyword == "v") {
      double x[3];
      for (double& c : x) {
        if (!cursor.number(c)) cursor.fail("vertex needs 3 coordinates");
      }
      positions.insert(positions.end(), x, x + 3);
    } else if (keyword == "vt") {
      double u = 0.0, v = 0.0;
      if (!cursor.number(u)) cursor.fail("texture coordinate needs at least 1 value");
      cursor.number(v);
      uvs.push_back(u);
      uvs.push_back(v);
    } else if (keyword == "f") {
      const long long vertex_count = static_cast<long long>(positions.size() / 3);
      const long long uv_count = static_cast<long long>(uvs.size() / 2);
      std::size_t corners = 0;
      for (std::string token = cursor.word(); !token.empty(); token = cursor.word(), ++corners) {
        long long v = 0, vt = 0;
        parse_obj_corner(cursor, token, v, vt);
        // Negative indices count back from the last element read so far.
        const long long vi = v > 0 ? v - 1 : vertex_count + v;
        if (vi < 0) cursor.fail("face refers to vertex " + std::to_string(v) + " before the first vertex");
        polygons.corners.push_back(vi);
        if (vt == 0) {
          all_corners_have_uv = false;
        } else {
          const long long ti = vt > 0 ? vt - 1 : uv_count + vt;
          if (ti < 0) cursor.fail("face refers to texture coordinate " + std::to_string(vt) + " before the first one");
          polygons.corner_uvs.push_back(ti);
        }
      }
      if (corners < 3) cursor.fail("face has " + std::to_string(corners) + " corners (at least 3 needed)");
      polygons.starts.push_back(polygons.corners.size());
      polygons.lines.push_back(static_cast<int>(l + 1));
      if (!current_material.empty() && (used_materials.empty() || used_materials.back() != current_material)) {
        used_materials.push_back(current_material);
      }
    } else if (keyword == "mtllib") {
      const std::string rest = cursor.rest();
      std::error_code ec;
      if (fs::is_regular_file(fs::path(path).parent_path() / rest, ec)) {
        libraries.push_back(rest);
      } else {
        // Several libraries may be listed on one line.
        std::istringstream names(rest);
        for (std::string name; names >> name;) libraries.push_back(name);
      }
    } else if (keyword == "usemtl") {
      current_material = cursor.rest();
    }
    // Normals, groups, smoothing groups, lines and points do not matter for a closed triangle surface.
  }

  const long long vertex_count = static_cast<long long>(positions.size() / 3);
  const long long uv_count = static_cast<long long>(uvs.size() / 2);
  for (std::size_t p = 0; p < polygons.count(); ++p) {
    for (std::size_t k = polygons.starts[p]; k < polygons.starts[p + 1]; ++k) {
      if (polygons.corners[k] >= vertex_count) {
        throw InvalidInput(path + ": line " + std::to_string(polygons.lines[p]) + ": face refers to vertex " +
                           std::to_string(polygons.corners[k] + 1) + " but the file has " +
                           std::to_string(vertex_count) + " vertices");
      }
      if (all_corners_have_uv && polygons.corner_uvs[k] >= uv_count) {
        throw InvalidInput(path + ": line " + std::to_string(polygons.lines[p]) +
                           ": face refers to texture coordinate " + std::to_string(polygons.corner_uvs[k] + 1) +
                           " but the file has " + std::to_string(uv_count));
      }
    }
  }

  Surface surface;
  surface.name = path;
  surface.V = to_matrix(positions, 3);
  surface.F = fan_triangulate(polygons, polygons.corners);
  // A file where only some faces have texture coordinates has no usable parametrisation.
  if (all_corners_have_uv && polygons.count() > 0) {
    surface.UV = to_matrix(uvs, 2);
    surface.FUV = fan_triangulate(polygons, polygons.corner_uvs);
  }

  if (!libraries.empty()) {
    const fs::path folder = fs::path(path).parent_path();
    std::string first_texture;
    const std::map<std::string, std::string> textures = load_material_textures(folder, libraries, first_texture);
    std::string texture;
    for (const std::string& material : used_materials) {
      const auto it = textures.find(material);
      if (it == textures.end()) continue;
      if (texture.empty()) {
        texture = it->second;
      } else if (it->second != texture && std::find(surface.other_textures.begin(), surface.other_textures.end(),
                                                    it->second) == surface.other_textures.end()) {
        surface.other_textures.push_back(it->second);  // one texture is carried: the caller warns about the rest
      }
    }
    if (texture.empty()) texture = first_texture;
    if (!texture.empty()) {
      surface.texture_path = resolve_texture(folder, texture);
      if (surface.texture_path.empty()) surface.missing_texture = texture;
    }
  }
  return surface;
}

// ---------------------------------------------------------------------------------------------------------------
// OFF

Surface read_off(const std::string& path) {
  std::string data = read_whole_file(path);
  const std::vector<const char*> lines = split_lines(data);
  std::size_t l = 0;
  // Advances to the next line with content; false at the end of the file.
  auto next_line = [&]() {
    for (; l < lines.size(); ++l) {
      LineCursor probe(path, static_cast<int>(l + 1), lines[l]);
      if (!probe.at_end()) return true;
    }
    return false;
  };

  if (!next_line()) throw InvalidInput(path + ": mesh has no faces");
  long long vertex_count = 0, face_count = 0;
  {
    LineCursor cursor(path, static_cast<int>(l + 1), lines[l]);
    const char* start = lines[l];
    while (*start == ' ' || *start == '\t') ++start;
    if (std::isalpha(static_cast<unsigned char>(*start))) {
      // "OFF", or a variant whose prefixes (ST, C, N) only add per-vertex values that this reader ignores.
      const std::string header = cursor.word();
      const std::size_t off = header.rfind("OFF");
      if (off == std::string::npos || off + 3 != header.size() ||
          header.substr(0, off).find_first_not_of("STCN") != std::string::npos) {
        cursor.fail("not an OFF file (header '" + header + "')");
      }
      if (cursor.at_end()) {
        // The counts stand on the next line.
        ++l;
        if (!next_line()) throw InvalidInput(path + ": file ends before the vertex and face counts");
        cursor = LineCursor(path, static_cast<int>(l + 1), lines[l]);
      }
    }
    if (!cursor.integer(vertex_count) || !cursor.integer(face_count)) cursor.fail("expected vertex and face counts");
    if (vertex_count < 0 || face_count < 0) cursor.fail("negative vertex or face count");
    ++l;
  }

  // Every item needs a line, so larger counts than lines are a truncated file, not an allocation to attempt.
  std::vector<double> positions;
  positions.reserve(3 * static_cast<std::size_t>(std::min<long long>(vertex_count, lines.size())));
  for (long long i = 0; i < vertex_count; ++i, ++l) {
    if (!next_line()) {
      throw InvalidInput(path + ": unexpected end of file after " + std::to_string(i) + " of " +
                         std::to_string(vertex_count) + " vertices");
    }
    LineCursor cursor(path, static_cast<int>(l + 1), lines[l]);
    for (int c = 0; c < 3; ++c) {
      double x = 0.0;
      if (!cursor.number(x)) cursor.fail("vertex " + std::to_string(i) + " needs 3 coordinates");
      positions.push_back(x);
    }
  }
  Polygons polygons;
  for (long long f = 0; f < face_count; ++f, ++l) {
    if (!next_line()) {
      throw InvalidInput(path + ": unexpected end of file after " + std::to_string(f) + " of " +
                         std::to_string(face_count) + " faces");
    }
    LineCursor cursor(path, static_cast<int>(l + 1), lines[l]);
    long long n = 0;
    if (!cursor.integer(n)) cursor.fail("face " + std::to_string(f) + " has no vertex count");
    if (n < 3) cursor.fail("face " + std::to_string(f) + " has " + std::to_string(n) + " vertices (at least 3 needed)");
    for (long long k = 0; k < n; ++k) {
      long long v = 0;
      if (!cursor.integer(v)) {
        cursor.fail("face " + std::to_string(f) + " lists " + std::to_string(k) + " of " + std::to_string(n) +
                    " vertex indices");
      }
      if (v < 0 || v >= vertex_count) {
        throw InvalidInput(path + ": face " + std::to_string(f) + " has vertex index " + std::to_string(v) +
                           " out of range [0, " + std::to_string(vertex_count) + ")");
      }
      polygons.corners.push_back(v);
    }
    // Anything after the indices is a face colour.
    polygons.starts.push_back(polygons.corners.size());
  }

  Surface surface;
  surface.name = path;
  surface.V = to_matrix(positions, 3);
  surface.F = fan_triangulate(polygons, polygons.corners);
  return surface;
}

// ---------------------------------------------------------------------------------------------------------------
// STL (ASCII and binary). Every facet carries its own three corners; corners at bitwise-equal positions are welded
// into shared vertices (what the format means, and what the pipeline's closedness check needs). The facet normals are
// ignored: the corners' order gives the orientation, as in the other formats. Written by hand: no Debian package
// reads STL short of Assimp, a large dependency for a forty-line format.

Surface read_stl(const std::string& path) {
  std::string data = read_whole_file(path);
  std::vector<double> positions;
  const bool ascii_header = data.compare(0, 5, "solid") == 0;
  std::uint32_t count = 0;
  if (data.size() >= 84) std::memcpy(&count, data.data() + 80, sizeof count);
  // A binary file may also start with "solid" in its 80-byte header; its size settles which it is.
  if (data.size() >= 84 && data.size() == 84 + 50 * std::size_t(count)) {
    positions.reserve(9 * std::size_t(count));
    for (std::uint32_t f = 0; f < count; ++f) {
      const char* facet = data.data() + 84 + 50 * std::size_t(f) + 12;  // after the normal
      for (int k = 0; k < 9; ++k) {
        float x = 0.0f;
        std::memcpy(&x, facet + 4 * k, sizeof x);
        positions.push_back(double(x));
      }
    }
  } else if (ascii_header) {
    const std::vector<const char*> lines = split_lines(data);
    int in_loop = -1;  // corners of the current loop, -1 outside one
    for (std::size_t l = 0; l < lines.size(); ++l) {
      LineCursor cursor(path, static_cast<int>(l + 1), lines[l]);
      const std::string keyword = cursor.word();
      if (keyword == "outer") {
        in_loop = 0;
      } else if (keyword == "vertex") {
        if (in_loop < 0) cursor.fail("vertex outside a facet's loop");
        for (int c = 0; c < 3; ++c) {
          double x = 0.0;
          if (!cursor.number(x)) cursor.fail("vertex needs 3 coordinates");
          positions.push_back(x);
        }
        ++in_loop;
      } else if (keyword == "endloop") {
        if (in_loop != 3) cursor.fail("facet has " + std::to_string(std::max(in_loop, 0)) + " vertices, not 3");
        in_loop = -1;
      }
    }
    if (in_loop >= 0) throw InvalidInput(path + ": file ends inside a facet");
  } else {
    throw InvalidInput(path + ": not an STL file (no 'solid' header, and " + std::to_string(data.size()) +
                       " bytes is not a binary STL's 84 + 50 per facet)");
  }
  Surface surface;
  surface.name = path;
  surface.V = to_matrix(positions, 3);
  surface.F.resize(surface.V.rows() / 3, 3);
  for (Eigen::Index f = 0; f < surface.F.rows(); ++f)
    for (int c = 0; c < 3; ++c) surface.F(f, c) = int(3 * f + c);
  weld_coincident_vertices(surface);
  return surface;
}

// ---------------------------------------------------------------------------------------------------------------
// PLY

enum class PlyType { Int8, UInt8, Int16, UInt16, Int32, UInt32, Float32, Float64 };

bool parse_ply_type(const std::string& name, PlyType& type) {
  static const std::map<std::string, PlyType> types = {
      {"char", PlyType::Int8},      {"int8", PlyType::Int8},       {"uchar", PlyType::UInt8},
      {"uint8", PlyType::UInt8},    {"short", PlyType::Int16},     {"int16", PlyType::Int16},
      {"ushort", PlyType::UInt16},  {"uint16", PlyType::UInt16},   {"int", PlyType::Int32},
      {"int32", PlyType::Int32},    {"uint", PlyType::UInt32},     {"uint32", PlyType::UInt32},
      {"float", PlyType::Float32},  {"float32", PlyType::Float32}, {"double", PlyType::Float64},
      {"float64", PlyType::Float64}};
  const auto it = types.find(name);
  if (it == types.end()) return false;
  type = it->second;
  return true;
}

std::size_t ply_type_size(PlyType type) {
  switch (type) {
    case PlyType::Int8:
    case PlyType::UInt8:
      return 1;
    case PlyType::Int16:
    case PlyType::UInt16:
      return 2;
    case PlyType::Int32:
    case PlyType::UInt32:
    case PlyType::Float32:
      return 4;
    case PlyType::Float64:
      return 8;
  }
  return 0;
}

struct PlyProperty {
  std::string name;
  PlyType type = PlyType::Float32;
  bool is_list = false;
  PlyType count_type = PlyType::UInt8;
};

struct PlyElement {
  std::string name;
  long long count = 0;
  std::vector<PlyProperty> properties;
};

// Reads PLY scalars from the body, ASCII tokens or little-endian binary values.
class PlyBody {
 public:
  PlyBody(const std::string& path, const std::string& data, std::size_t offset, bool binary)
      : path_(path), data_(data), pos_(offset), binary_(binary) {}

  void set_context(const std::string& element, long long item) {
    element_ = &element;
    item_ = item;
  }

  [[noreturn]] void fail(const std::string& problem) const {
    throw InvalidInput(path_ + ": " + problem + " (element '" + *element_ + "', item " + std::to_string(item_) + ")");
  }

  std::size_t remaining() const { return data_.size() - pos_; }

  double scalar(PlyType type) {
    if (!binary_) return ascii_scalar(type);
    const std::size_t size = ply_type_size(type);
    if (remaining() < size) fail("file is truncated");
    const char* p = data_.data() + pos_;
    pos_ += size;
    switch (type) {
      case PlyType::Int8:
        return load<std::int8_t>(p);
      case PlyType::UInt8:
        return load<std::uint8_t>(p);
      case PlyType::Int16:
        return load<std::int16_t>(p);
      case PlyType::UInt16:
        return load<std::uint16_t>(p);
      case PlyType::Int32:
        return load<std::int32_t>(p);
      case PlyType::UInt32:
        return load<std::uint32_t>(p);
      case PlyType::Float32:
        return load<float>(p);
      case PlyType::Float64:
        return load<double>(p);
    }
    return 0.0;
  }

 private:
  template <typename T>
  static double load(const char* p) {
    T value;
    std::memcpy(&value, p, sizeof value);
    return static_cast<double>(value);
  }

  double ascii_scalar(PlyType type) {
    while (pos_ < data_.size() && std::isspace(static_cast<unsigned char>(data_[pos_]))) ++pos_;
    if (pos_ == data_.size()) fail("unexpected end of file");
    std::size_t end = pos_;
    while (end < data_.size() && !std::isspace(static_cast<unsigned char>(data_[end]))) ++end;
    const std::string token = data_.substr(pos_, end - pos_);
    pos_ = end;
    char* stop = nullptr;
    const double value = std::strtod(token.c_str(), &stop);
    if (stop != token.c_str() + token.size()) fail("bad number '" + token + "'");
    if (type != PlyType::Float32 && type != PlyType::Float64 && value != std::floor(value)) {
      fail("bad integer '" + token + "'");
    }
    return value;
  }

  const std::string& path_;
  const std::string& data_;
  std::size_t pos_;
  bool binary_;
  const std::string* element_ = nullptr;
  long long item_ = 0;
};

Surface read_ply(const std::string& path) {
  const std::string data = read_whole_file(path);
  auto fail = [&](const std::string& problem) -> void { throw InvalidInput(path + ": " + problem); };

  // Header: text lines up to "end_header".
  std::vector<PlyElement> elements;
  bool binary = false;
  bool have_format = false;
  std::size_t pos = 0;
  int line_number = 0;
  bool ended = false;
  while (pos < data.size() && !ended) {
    std::size_t eol = data.find('\n', pos);
    if (eol == std::string::npos) eol = data.size();
    std::string line = data.substr(pos, eol - pos);
    pos = std::min(eol + 1, data.size());
    ++line_number;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    std::istringstream in(line);
    std::string keyword;
    in >> keyword;
    const std::string where = "header line " + std::to_string(line_number) + ": ";
    if (line_number == 1) {
      if (keyword != "ply") fail("not a PLY file (first line is not 'ply')");
      continue;
    }
    if (keyword.empty() || keyword == "comment" || keyword == "obj_info") continue;
    if (keyword == "format") {
      std::string format;
      in >> format;
      if (format == "ascii") {
        binary = false;
      } else if (format == "binary_little_endian") {
        binary = true;
      } else if (format == "binary_big_endian") {
        fail("binary big-endian PLY is not supported");
      } else {
        fail(where + "unknown format '" + format + "'");
      }
      have_format = true;
    } else if (keyword == "element") {
      PlyElement element;
      if (!(in >> element.name >> element.count) || element.count < 0) fail(where + "bad element line '" + line + "'");
      elements.push_back(element);
    } else if (keyword == "property") {
      if (elements.empty()) fail(where + "property before any element");
      PlyProperty property;
      std::string type;
      in >> type;
      if (type == "list") {
        std::string count_type, item_type;
        in >> count_type >> item_type >> property.name;
        property.is_list = true;
        if (!parse_ply_type(count_type, property.count_type) || !parse_ply_type(item_type, property.type)) {
          fail(where + "unknown type in '" + line + "'");
        }
      } else {
        in >> property.name;
        if (!parse_ply_type(type, property.type)) fail(where + "unknown type '" + type + "'");
      }
      if (property.name.empty()) fail(where + "property without a name");
      elements.back().properties.push_back(property);
    } else if (keyword == "end_header") {
      ended = true;
    } else {
      fail(where + "unexpected '" + keyword + "'");
    }
  }
  if (!ended) fail("PLY header has no end_header");
  if (!have_format) fail("PLY header has no format line");

  PlyBody body(path, data, pos, binary);
  std::vector<double> positions, uvs;
  bool have_vertices = false;
  bool have_uv = false;
  Polygons polygons;
  std::vector<long long> face_of_polygon;

  for (const PlyElement& element : elements) {
    // Each item takes at least one byte (binary) or two characters (ASCII), so a larger count is a truncation.
    std::size_t min_item_size = 0;
    for (const PlyProperty& p : element.properties)
      min_item_size += binary ? ply_type_size(p.is_list ? p.count_type : p.type) : 2;
    if (static_cast<double>(element.count) * static_cast<double>(min_item_size) >
        static_cast<double>(body.remaining())) {
      fail("file is truncated (element '" + element.name + "' declares " + std::to_string(element.count) + " items)");
    }
    if (element.name == "vertex" && !have_vertices) {
      have_vertices = true;
      int xyz[3] = {-1, -1, -1};
      int uv[2] = {-1, -1};
      static const char* uv_names[][2] = {
          {"u", "v"}, {"s", "t"}, {"texture_u", "texture_v"}, {"texture_s", "texture_t"}};
      for (int i = 0; i < static_cast<int>(element.properties.size()); ++i) {
        const PlyProperty& p = element.properties[i];
        if (p.is_list) continue;
        for (int c = 0; c < 3; ++c) {
          if (p.name == std::string(1, static_cast<char>('x' + c))) xyz[c] = i;
        }
        for (const auto& names : uv_names) {
          for (int c = 0; c < 2; ++c) {
            if (p.name == names[c] && uv[c] < 0) uv[c] = i;
          }
        }
      }
      if (xyz[0] < 0 || xyz[1] < 0 || xyz[2] < 0) fail("vertex element lacks an x, y or z property");
      have_uv = uv[0] >= 0 && uv[1] >= 0;
      positions.resize(3 * static_cast<std::size_t>(element.count));
      if (have_uv) uvs.resize(2 * static_cast<std::size_t>(element.count));
      std::vector<double> values(element.properties.size());
      for (long long item = 0; item < element.count; ++item) {
        body.set_context(element.name, item);
        for (std::size_t i = 0; i < element.properties.size(); ++i) {
          const PlyProperty& p = element.properties[i];
          if (!p.is_list) {
            values[i] = body.scalar(p.type);
            continue;
          }
          const double n = body.scalar(p.count_type);
          for (double k = 0; k < n; ++k) body.scalar(p.type);
        }
        for (int c = 0; c < 3; ++c) positions[3 * item + c] = values[xyz[c]];
        if (have_uv) {
          for (int c = 0; c < 2; ++c) uvs[2 * item + c] = values[uv[c]];
        }
      }
    } else if (element.name == "face" && polygons.count() == 0) {
      int list = -1;
      for (int i = 0; i < static_cast<int>(element.properties.size()); ++i) {
        const PlyProperty& p = element.properties[i];
        if (p.is_list && (p.name == "vertex_indices" || p.name == "vertex_index") && list < 0) list = i;
      }
      if (list < 0) fail("face element lacks a 'vertex_indices' list property");
      for (long long item = 0; item < element.count; ++item) {
        body.set_context(element.name, item);
        for (int i = 0; i < static_cast<int>(element.properties.size()); ++i) {
          const PlyProperty& p = element.properties[i];
          if (!p.is_list) {
            body.scalar(p.type);
            continue;
          }
          const double n = body.scalar(p.count_type);
          if (n < 0) body.fail("negative list length");
          if (i == list) {
            if (n < 3)
              body.fail("face has " + std::to_string(static_cast<long long>(n)) + " vertices (at least 3 needed)");
            for (double k = 0; k < n; ++k) {
              const double v = body.scalar(p.type);
              if (v != std::floor(v)) body.fail("non-integer vertex index");
              polygons.corners.push_back(static_cast<long long>(std::clamp(v, -1e18, 1e18)));
            }
            polygons.starts.push_back(polygons.corners.size());
            face_of_polygon.push_back(item);
          } else {
            for (double k = 0; k < n; ++k) body.scalar(p.type);
          }
        }
      }
    } else {
      // Edges, materials and the like: read past them.
      for (long long item = 0; item < element.count; ++item) {
        body.set_context(element.name, item);
        for (const PlyProperty& p : element.properties) {
          const double n = p.is_list ? body.scalar(p.count_type) : 1.0;
          for (double k = 0; k < n; ++k) body.scalar(p.type);
        }
      }
    }
  }
  if (!have_vertices) fail("PLY file has no vertex element");

  const long long vertex_count = static_cast<long long>(positions.size() / 3);
  for (std::size_t p = 0; p < polygons.count(); ++p) {
    for (std::size_t k = polygons.starts[p]; k < polygons.starts[p + 1]; ++k) {
      const long long v = polygons.corners[k];
      if (v < 0 || v >= vertex_count) {
        throw InvalidInput(path + ": face " + std::to_string(face_of_polygon[p]) + " has vertex index " +
                           std::to_string(v) + " out of range [0, " + std::to_string(vertex_count) + ")");
      }
    }
  }

  Surface surface;
  surface.name = path;
  surface.V = to_matrix(positions, 3);
  surface.F = fan_triangulate(polygons, polygons.corners);
  if (have_uv && surface.F.rows() > 0) {
    surface.UV = to_matrix(uvs, 2);
    surface.FUV = surface.F;  // per-vertex coordinates: every corner uses its vertex's entry
  }
  return surface;
}

// ---------------------------------------------------------------------------------------------------------------
// Writing

void append_number(std::string& out, double x) {
  // Shortest text that reads back to the same double.
  char buffer[32];
  const auto result = std::to_chars(buffer, buffer + sizeof buffer, x);
  out.append(buffer, result.ptr);
}

void append_number(std::string& out, long long x) {
  char buffer[32];
  const auto result = std::to_chars(buffer, buffer + sizeof buffer, x);
  out.append(buffer, result.ptr);
}

// A file written through a buffer that is handed to the file whenever it holds a megabyte: the mesh writers format
// into `text` and call `flush_if_full` after each line or record. Writing the whole file from one string held it
// all in memory at once, and its reallocations twice: at small sizes the output writing was the run's peak of memory
// (a slice of 48 k vertices: 47 MB). Closed by finish(), or, after an error, by the destructor.
class ChunkedFile {
 public:
  explicit ChunkedFile(const std::string& path) : path_(path), file_(std::fopen(path.c_str(), "wb")) {
    if (file_ == nullptr) throw IoError(path + ": cannot open file for writing (" + std::strerror(errno) + ")");
    text.reserve(kChunk + 4096);
  }
  ~ChunkedFile() {
    if (file_ != nullptr) std::fclose(file_);
  }
  ChunkedFile(const ChunkedFile&) = delete;
  ChunkedFile& operator=(const ChunkedFile&) = delete;

  void flush_if_full() {
    if (text.size() >= kChunk) flush();
  }
  void finish() {
    flush();
    const bool closed = std::fclose(file_) == 0;
    file_ = nullptr;
    if (!closed) throw IoError(path_ + ": cannot write file (" + std::strerror(errno) + ")");
  }

  std::string text;

 private:
  static constexpr std::size_t kChunk = std::size_t(1) << 20;
  void flush() {
    if (!text.empty() && std::fwrite(text.data(), 1, text.size(), file_) != text.size())
      throw IoError(path_ + ": cannot write file (" + std::strerror(errno) + ")");
    text.clear();
  }
  std::string path_;
  std::FILE* file_;
};

void check_faces(const std::string& path, const std::string& what, const TriIndices& F, Eigen::Index count) {
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    for (int k = 0; k < 3; ++k) {
      if (F(f, k) < 0 || F(f, k) >= count) {
        throw InvalidInput(path + ": cannot write face " + std::to_string(f) + ": " + what + " index " +
                           std::to_string(F(f, k)) + " out of range [0, " + std::to_string(count) + ")");
      }
    }
  }
}

void check_vertices(const std::string& path, const Eigen::MatrixXd& V) {
  if (V.cols() != 3 && V.rows() > 0) {
    throw InvalidInput(path + ": cannot write vertices with " + std::to_string(V.cols()) + " coordinates");
  }
}

}  // namespace

Surface read_surface(const std::string& path) {
  const std::string extension = lower(fs::path(path).extension().string());
  Surface surface;
  if (extension == ".obj") {
    surface = read_obj(path);
  } else if (extension == ".off") {
    surface = read_off(path);
  } else if (extension == ".ply") {
    surface = read_ply(path);
  } else if (extension == ".stl") {
    surface = read_stl(path);
  } else {
    throw InvalidInput(path + ": unknown mesh file extension '" + extension + "' (expected .obj, .off, .ply or .stl)");
  }
  // Empty, non-finite and out-of-range input is rejected here, with the path in the message.
  validate_surface(surface, false);
  return surface;
}

void write_obj(const std::string& path, const Eigen::MatrixXd& V, const TriIndices& F, const Eigen::MatrixXd& UV,
               const TriIndices& FUV, const std::string& mtl_name) {
  check_vertices(path, V);
  check_faces(path, "vertex", F, V.rows());
  const bool has_uv = UV.rows() > 0;
  const bool per_corner = has_uv && FUV.rows() > 0;
  if (has_uv && UV.cols() != 2) throw InvalidInput(path + ": texture coordinates must have 2 columns");
  if (per_corner) {
    if (FUV.rows() != F.rows()) {
      throw InvalidInput(path + ": FUV has " + std::to_string(FUV.rows()) + " rows, F has " + std::to_string(F.rows()));
    }
    check_faces(path, "texture", FUV, UV.rows());
  } else if (has_uv && UV.rows() != V.rows()) {
    throw InvalidInput(path + ": per-vertex UV has " + std::to_string(UV.rows()) + " rows, V has " +
                       std::to_string(V.rows()));
  }

  ChunkedFile file(path);
  std::string& out = file.text;
  out += "# morphmap\n";
  if (!mtl_name.empty()) out += "mtllib " + mtl_name + "\n";
  for (Eigen::Index i = 0; i < V.rows(); ++i) {
    out += "v";
    for (int c = 0; c < 3; ++c) {
      out += ' ';
      append_number(out, V(i, c));
    }
    out += '\n';
    file.flush_if_full();
  }
  for (Eigen::Index i = 0; i < UV.rows(); ++i) {
    out += "vt ";
    append_number(out, UV(i, 0));
    out += ' ';
    append_number(out, UV(i, 1));
    out += '\n';
    file.flush_if_full();
  }
  if (!mtl_name.empty()) out += "usemtl morphmap\n";
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    out += "f";
    for (int k = 0; k < 3; ++k) {
      out += ' ';
      append_number(out, static_cast<long long>(F(f, k)) + 1);
      if (has_uv) {
        out += '/';
        append_number(out, static_cast<long long>(per_corner ? FUV(f, k) : F(f, k)) + 1);
      }
    }
    out += '\n';
    file.flush_if_full();
  }
  file.finish();
}

void write_mtl(const std::string& path, const std::string& texture_name) {
  ChunkedFile file(path);
  file.text = "# morphmap\nnewmtl morphmap\nKa 1 1 1\nKd 1 1 1\nKs 0 0 0\nillum 1\n";
  if (!texture_name.empty()) file.text += "map_Kd " + texture_name + "\n";
  file.finish();
}

PerVertexUvMesh per_vertex_uv(const Eigen::MatrixXd& V, const TriIndices& F, const Eigen::MatrixXd& UV,
                              const TriIndices& FUV) {
  if (FUV.rows() != F.rows() || UV.cols() != 2)
    throw InvalidInput("per_vertex_uv: need FUV with a row per face (" + std::to_string(F.rows()) + ") and UV #T by 2");
  PerVertexUvMesh out;
  out.F.resize(F.rows(), 3);
  // copies[v]: (texture coordinate index, output vertex) of each copy of v made so far; a vertex has few. Copies are
  // told apart by the coordinates' values, not their indices (the seam split gives every corner its own index), and
  // values within 1e-9 are one (the split computes a vertex's coordinate per triangle, which may differ by rounding).
  std::vector<std::vector<std::pair<int, int>>> copies(std::size_t(V.rows()));
  for (Eigen::Index f = 0; f < F.rows(); ++f)
    for (int c = 0; c < 3; ++c) {
      const int v = F(f, c), t = FUV(f, c);
      if (v < 0 || v >= V.rows() || t < 0 || t >= UV.rows())
        throw InvalidInput("per_vertex_uv: face " + std::to_string(f) + " has an index out of range");
      auto& list = copies[std::size_t(v)];
      auto found = std::find_if(list.begin(), list.end(), [&](const std::pair<int, int>& e) {
        return (UV.row(e.first) - UV.row(t)).squaredNorm() <= 1e-18;
      });
      if (found == list.end()) {
        list.emplace_back(t, int(out.vertex.size()));
        out.vertex.push_back(v);
        found = list.end() - 1;
      }
      out.F(f, c) = found->second;
    }
  out.V.resize(Eigen::Index(out.vertex.size()), 3);
  out.UV.resize(Eigen::Index(out.vertex.size()), 2);
  for (const auto& list : copies)
    for (const auto& [t, w] : list) {
      out.V.row(w) = V.row(out.vertex[std::size_t(w)]);
      out.UV.row(w) = UV.row(t);
    }
  return out;
}

void write_ply(const std::string& path, const Eigen::MatrixXd& V, const TriIndices& F, const Eigen::MatrixXd& UV) {
  check_vertices(path, V);
  check_faces(path, "vertex", F, V.rows());
  const bool has_uv = UV.rows() > 0;
  if (has_uv && (UV.rows() != V.rows() || UV.cols() != 2)) {
    throw InvalidInput(path + ": per-vertex UV is " + std::to_string(UV.rows()) + " by " + std::to_string(UV.cols()) +
                       ", expected " + std::to_string(V.rows()) + " by 2");
  }
  ChunkedFile file(path);
  std::string& out = file.text;
  out += "ply\nformat binary_little_endian 1.0\ncomment morphmap\nelement vertex " + std::to_string(V.rows()) +
         "\nproperty double x\nproperty double y\nproperty double z\n";
  if (has_uv) out += "property float u\nproperty float v\n";
  out += "element face " + std::to_string(F.rows()) + "\nproperty list uchar int vertex_indices\nend_header\n";
  auto put = [&out](const auto& value) { out.append(reinterpret_cast<const char*>(&value), sizeof value); };
  for (Eigen::Index i = 0; i < V.rows(); ++i) {
    for (int c = 0; c < 3; ++c) put(V(i, c));
    if (has_uv) {
      put(static_cast<float>(UV(i, 0)));
      put(static_cast<float>(UV(i, 1)));
    }
    file.flush_if_full();
  }
  for (Eigen::Index f = 0; f < F.rows(); ++f) {
    put(static_cast<std::uint8_t>(3));
    for (int k = 0; k < 3; ++k) put(static_cast<std::int32_t>(F(f, k)));
    file.flush_if_full();
  }
  file.finish();
}

}  // namespace morphmap
