// TEST STUB — NOT UNREAL ENGINE (see CoreMinimal.h). Compile-only.
#pragma once

#include "CoreMinimal.h"

class IPlugin {
 public:
  virtual ~IPlugin() = default;
  virtual FString GetBaseDir() const = 0;
};
class IPluginManager {
 public:
  static IPluginManager& Get() { static IPluginManager m; return m; }
  TSharedPtr<IPlugin> FindPlugin(const FString&) { return nullptr; }
};
