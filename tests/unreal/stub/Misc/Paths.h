// TEST STUB — NOT UNREAL ENGINE (see CoreMinimal.h).
#pragma once

#include "CoreMinimal.h"

struct FPaths {
  static inline FString StubProjectContentDir;  // stub: set by the test
  static FString ProjectContentDir() { return StubProjectContentDir; }
  static bool IsRelative(const FString& p) { return p.Std().empty() || p.Std()[0] != '/'; }
  static FString Combine(const FString& a, const FString& b) {
    std::string s = a.Std();
    if (!s.empty() && s.back() != '/') s += '/';
    return FString(s + b.Std());
  }
};
