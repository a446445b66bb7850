// ReadNpy for the Unreal plugin's tests (test_component.cpp,
// test_transflower_component.cpp): the fixtures' .npy files.
#pragma once

#include <cstdio>
#include <cstring>
#include <string>
#include <vector>

// A little-endian float32 .npy (numpy format 1.0) of 1 to 4 dimensions:
// *rows = the first, *cols = the product of the others (1 for 1-D).
inline std::vector<float> ReadNpy(const std::string& path, size_t* rows, size_t* cols) {
  std::vector<float> out;
  std::FILE* f = std::fopen(path.c_str(), "rb");
  if (!f) return out;
  unsigned char head[10];
  if (std::fread(head, 1, 10, f) != 10 || std::memcmp(head, "\x93NUMPY", 6) != 0 || head[6] != 1) {
    std::fclose(f);
    return out;
  }
  size_t hlen = head[8] | (head[9] << 8);
  std::string h(hlen, '\0');
  if (std::fread(&h[0], 1, hlen, f) != hlen || h.find("'<f4'") == std::string::npos) {
    std::fclose(f);
    return out;
  }
  size_t open = h.find('(', h.find("'shape'"));
  size_t d[4] = {0, 1, 1, 1};
  if (std::sscanf(h.c_str() + open, "(%zu, %zu, %zu, %zu", &d[0], &d[1], &d[2], &d[3]) < 1) {
    std::fclose(f);
    return out;
  }
  *rows = d[0];
  *cols = d[1] * d[2] * d[3];
  out.resize(*rows * *cols);
  if (std::fread(out.data(), 4, out.size(), f) != out.size()) out.clear();
  std::fclose(f);
  return out;
}
