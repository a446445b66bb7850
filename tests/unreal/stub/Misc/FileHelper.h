// TEST STUB — NOT UNREAL ENGINE (see CoreMinimal.h).
#pragma once

#include "CoreMinimal.h"

struct FFileHelper {
  static bool LoadFileToArray(TArray<uint8>& Out, const TCHAR* Path) {
    std::FILE* f = std::fopen(Path, "rb");
    if (!f) return false;
    std::fseek(f, 0, SEEK_END);
    long n = std::ftell(f);
    std::fseek(f, 0, SEEK_SET);
    Out.SetNum(static_cast<int32>(n));
    bool ok = std::fread(Out.GetData(), 1, static_cast<size_t>(n), f) == static_cast<size_t>(n);
    std::fclose(f);
    return ok;
  }
};
