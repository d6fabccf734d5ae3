// Feeds SDK v1 data packets to the Livox SDK 2.3.0's own LVX writer (sample/lidar_lvx_file,
// LvxFileHandle) so scripts/compare_lvx_with_vendor_writer.py can compare its bytes with ours.
// Input (stdin-free, argv[1]): u8 device_count, device_count x 59-byte LvxDeviceInfo, then frames:
// u32 package_count, package_count x (u8 device_index, u16 length, length bytes of the packet).
// Writes the vendor's YYYY-MM-DD_hh-mm-ss.lvx in the current directory and prints its name.
#include <cstdio>
#include <cstring>
#include <fstream>
#include <list>
#include <vector>
#include "lvx_file.h"

int main(int argc, char **argv) {
  if (argc != 2) { std::fprintf(stderr, "usage: %s INPUT\n", argv[0]); return 2; }
  std::ifstream in(argv[1], std::ios::binary);
  std::vector<char> buf((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  size_t pos = 0;
  auto take = [&](void *dst, size_t n) { std::memcpy(dst, buf.data() + pos, n); pos += n; };
  LvxFileHandle handle;
  uint8_t n_dev = 0;
  take(&n_dev, 1);
  for (int k = 0; k < n_dev; k++) {
    LvxDeviceInfo info;
    take(&info, sizeof(info));
    handle.AddDeviceInfo(info);
  }
  if (!handle.InitLvxFile()) { std::fprintf(stderr, "cannot create the lvx file\n"); return 1; }
  handle.InitLvxFileHeader();
  while (pos < buf.size()) {
    uint32_t n_pk = 0;
    take(&n_pk, 4);
    std::list<LvxBasePackDetail> frame;
    for (uint32_t k = 0; k < n_pk; k++) {
      uint8_t dev = 0;
      uint16_t len = 0;
      take(&dev, 1);
      take(&len, 2);
      std::vector<uint8_t> pkt(len + 8);
      take(pkt.data(), len);
      LvxBasePackDetail detail;
      std::memset(&detail, 0, sizeof(detail));
      handle.BasePointsHandle(reinterpret_cast<LivoxEthPacket *>(pkt.data()), detail);
      detail.device_index = dev;
      frame.push_back(detail);
    }
    handle.SaveFrameToLvxFile(frame);
  }
  handle.CloseLvxFile();
  return 0;
}
