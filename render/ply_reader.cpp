#include "render/ply_reader.h"

#include <cstdint>
#include <cstring>
#include <fstream>
#include <iterator>
#include <optional>
#include <sstream>

namespace previs {

namespace {

enum class PlyType { Int8, UInt8, Int16, UInt16, Int32, UInt32, Float32, Float64 };

std::optional<PlyType> parseType(const std::string& s) {
    if (s == "char" || s == "int8") return PlyType::Int8;
    if (s == "uchar" || s == "uint8") return PlyType::UInt8;
    if (s == "short" || s == "int16") return PlyType::Int16;
    if (s == "ushort" || s == "uint16") return PlyType::UInt16;
    if (s == "int" || s == "int32") return PlyType::Int32;
    if (s == "uint" || s == "uint32") return PlyType::UInt32;
    if (s == "float" || s == "float32") return PlyType::Float32;
    if (s == "double" || s == "float64") return PlyType::Float64;
    return std::nullopt;
}

size_t typeSize(PlyType t) {
    switch (t) {
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

struct Property {
    std::string name;
    PlyType type = PlyType::Float32;
    bool isList = false;
    PlyType countType = PlyType::UInt8;
};

struct Element {
    std::string name;
    size_t count = 0;
    std::vector<Property> properties;
};

// Reads values one at a time from the body, binary little endian or ascii.
class Reader {
public:
    Reader(const std::string& data, size_t pos, bool ascii)
        : data_(data), pos_(pos), ascii_(ascii) {
        if (ascii_) text_.str(data_.substr(pos_));
    }

    std::optional<double> read(PlyType t) {
        if (ascii_) {
            double v;
            if (!(text_ >> v)) return std::nullopt;
            return v;
        }
        size_t n = typeSize(t);
        if (pos_ + n > data_.size()) return std::nullopt;
        const char* p = data_.data() + pos_;
        pos_ += n;
        // x86-64 and the target ARM boards are little endian, like the files.
        switch (t) {
            case PlyType::Int8:
                return double(int8_t(*p));
            case PlyType::UInt8:
                return double(uint8_t(*p));
            case PlyType::Int16:
                return double(load<int16_t>(p));
            case PlyType::UInt16:
                return double(load<uint16_t>(p));
            case PlyType::Int32:
                return double(load<int32_t>(p));
            case PlyType::UInt32:
                return double(load<uint32_t>(p));
            case PlyType::Float32:
                return double(load<float>(p));
            case PlyType::Float64:
                return load<double>(p);
        }
        return std::nullopt;
    }

private:
    template <typename T>
    static T load(const char* p) {
        T v;
        std::memcpy(&v, p, sizeof(T));
        return v;
    }

    const std::string& data_;
    size_t pos_;
    bool ascii_;
    std::istringstream text_;
};

}  // namespace

Result<PlyMesh> readPly(const std::string& path) {
    std::ifstream file(path, std::ios::binary);
    if (!file) return makeError("{}: cannot open the PLY file", path);
    std::string data((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());

    size_t headerEnd = data.find("end_header");
    if (data.compare(0, 3, "ply") != 0 || headerEnd == std::string::npos)
        return makeError("{}: not a PLY file (no 'ply' magic or 'end_header')", path);
    size_t bodyStart = data.find('\n', headerEnd);
    if (bodyStart == std::string::npos) return makeError("{}: PLY header is not terminated", path);
    ++bodyStart;

    std::istringstream header(data.substr(0, headerEnd));
    std::vector<Element> elements;
    bool ascii = false;
    std::string line;
    while (std::getline(header, line)) {
        std::istringstream words(line);
        std::string keyword;
        words >> keyword;
        if (keyword == "format") {
            std::string format;
            words >> format;
            if (format == "ascii") {
                ascii = true;
            } else if (format != "binary_little_endian") {
                return makeError(
                    "{}: PLY format '{}' is not supported (ascii or "
                    "binary_little_endian)",
                    path, format);
            }
        } else if (keyword == "element") {
            Element e;
            words >> e.name >> e.count;
            elements.push_back(e);
        } else if (keyword == "property") {
            if (elements.empty()) return makeError("{}: PLY property before any element", path);
            Property p;
            std::string type;
            words >> type;
            if (type == "list") {
                std::string countType;
                std::string itemType;
                words >> countType >> itemType;
                auto ct = parseType(countType);
                auto it = parseType(itemType);
                if (!ct || !it) return makeError("{}: unknown PLY list type in '{}'", path, line);
                p.isList = true;
                p.countType = *ct;
                p.type = *it;
            } else {
                auto t = parseType(type);
                if (!t) return makeError("{}: unknown PLY property type in '{}'", path, line);
                p.type = *t;
            }
            words >> p.name;
            elements.back().properties.push_back(p);
        }
    }

    PlyMesh mesh;
    Reader reader(data, bodyStart, ascii);
    for (const Element& e : elements) {
        bool isVertex = e.name == "vertex";
        bool isFace = e.name == "face";
        if (isVertex) mesh.positions.reserve(e.count);
        std::vector<uint32_t> polygon;
        for (size_t i = 0; i < e.count; ++i) {
            glm::vec3 position(0.0f);
            for (const Property& p : e.properties) {
                if (p.isList) {
                    auto n = reader.read(p.countType);
                    if (!n || *n < 0)
                        return makeError("{}: PLY data ends early in {} {}", path, e.name, i);
                    polygon.clear();
                    for (size_t k = 0; k < size_t(*n); ++k) {
                        auto v = reader.read(p.type);
                        if (!v || *v < 0)
                            return makeError("{}: bad or missing vertex index in {} {}", path,
                                             e.name, i);
                        polygon.push_back(uint32_t(*v));
                    }
                    if (isFace && (p.name == "vertex_indices" || p.name == "vertex_index")) {
                        for (size_t k = 2; k < polygon.size(); ++k)
                            mesh.triangles.push_back({polygon[0], polygon[k - 1], polygon[k]});
                    }
                    continue;
                }
                auto v = reader.read(p.type);
                if (!v) return makeError("{}: PLY data ends early in {} {}", path, e.name, i);
                if (isVertex && p.name == "x") position.x = float(*v);
                if (isVertex && p.name == "y") position.y = float(*v);
                if (isVertex && p.name == "z") position.z = float(*v);
            }
            if (isVertex) mesh.positions.push_back(position);
        }
    }
    for (const glm::uvec3& t : mesh.triangles) {
        if (t.x >= mesh.positions.size() || t.y >= mesh.positions.size() ||
            t.z >= mesh.positions.size())
            return makeError("{}: a face uses a vertex index beyond the {} vertices", path,
                             mesh.positions.size());
    }
    return mesh;
}

}  // namespace previs
