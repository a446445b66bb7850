// TEST STUB — NOT UNREAL ENGINE (see CoreMinimal.h).
#pragma once

#include "CoreMinimal.h"

class IModuleInterface {
 public:
  virtual ~IModuleInterface() = default;
  virtual void StartupModule() {}
  virtual void ShutdownModule() {}
};
class FDefaultModuleImpl : public IModuleInterface {};

// Stub: a factory function the test calls instead of the module manager.
#define IMPLEMENT_MODULE(Class, Name) \
  IModuleInterface* StubCreateModule_##Name() { return new Class(); }
