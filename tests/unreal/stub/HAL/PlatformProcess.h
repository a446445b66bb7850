// TEST STUB — NOT UNREAL ENGINE (see CoreMinimal.h). Compile-only.
#pragma once

#include "CoreMinimal.h"

struct FPlatformProcess {
  static void* GetDllHandle(const TCHAR*) { return nullptr; }
  static void FreeDllHandle(void*) {}
};
