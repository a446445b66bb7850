// TEST STUB — NOT UNREAL ENGINE (see CoreMinimal.h).
#pragma once

#include "CoreMinimal.h"

class UObject {
 public:
  virtual ~UObject() = default;
};

enum ELevelTick { LEVELTICK_TimeOnly = 0, LEVELTICK_ViewportsOnly = 1, LEVELTICK_All = 2, LEVELTICK_PauseTick = 3 };
namespace EEndPlayReason {
enum Type { Destroyed, LevelTransition, EndPlayInEditor, RemovedFromWorld, Quit };
}
struct FActorComponentTickFunction {
  bool bCanEverTick = false;
};

class UActorComponent : public UObject {
 public:
  typedef UActorComponent Super;  // UHT's GENERATED_BODY provides Super in the real engine
  FActorComponentTickFunction PrimaryComponentTick;
  virtual void BeginPlay() {}
  virtual void EndPlay(const EEndPlayReason::Type) {}
  virtual void TickComponent(float, ELevelTick, FActorComponentTickFunction*) {}
};
