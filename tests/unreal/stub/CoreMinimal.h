// TEST STUB — NOT UNREAL ENGINE. The few Core types and macros the Duolando
// plugin's C++ uses, just enough to compile (and run, tests/unreal/
// test_component.cpp) the plugin's sources with g++ in CI (.ci/ffi.sh).
// Semantics are simplified: TCHAR is char (UE uses a wide type on some
// platforms; the plugin converts only through TEXT/TCHAR_TO_UTF8/
// UTF8_TO_TCHAR), containers are std:: wrappers, reflection macros expand
// to nothing. Never ship; it is no part of the plugin.
#pragma once

#include <cstdint>
#include <cstdio>
#include <functional>
#include <memory>
#include <string>
#include <vector>

using int32 = int32_t;
using int64 = int64_t;
using uint8 = uint8_t;
using uint32 = uint32_t;
using uint64 = uint64_t;
using TCHAR = char;

#define TEXT(s) s
#define UTF8_TO_TCHAR(s) (s)
#define TCHAR_TO_UTF8(s) (s)
#ifndef PLATFORM_WINDOWS
#define PLATFORM_WINDOWS 0
#endif

// Reflection: nothing (UHT's generated code is not part of the stub).
#define UCLASS(...)
#define USTRUCT(...)
#define UPROPERTY(...)
#define UFUNCTION(...)
#define GENERATED_BODY()

class FString {
 public:
  FString() = default;
  FString(const char* s) : s_(s ? s : "") {}
  FString(std::string s) : s_(std::move(s)) {}
  const TCHAR* operator*() const { return s_.c_str(); }
  int32 Len() const { return static_cast<int32>(s_.size()); }
  bool IsEmpty() const { return s_.empty(); }
  bool operator==(const FString& o) const { return s_ == o.s_; }
  const std::string& Std() const { return s_; }  // stub only
  template <typename... A>
  static FString Printf(const TCHAR* Format, A... Args) {
    int n = std::snprintf(nullptr, 0, Format, Args...);
    std::string s(n > 0 ? static_cast<size_t>(n) : 0, '\0');
    if (n > 0) std::snprintf(&s[0], s.size() + 1, Format, Args...);
    return FString(std::move(s));
  }
 private:
  std::string s_;
};

template <typename T>
class TArray {
 public:
  TArray() = default;
  TArray(std::initializer_list<T> l) : v_(l) {}
  int32 Num() const { return static_cast<int32>(v_.size()); }
  void SetNum(int32 n) { v_.resize(static_cast<size_t>(n)); }
  void SetNumUninitialized(int32 n) { v_.resize(static_cast<size_t>(n)); }
  int32 Add(const T& x) { v_.push_back(x); return Num() - 1; }
  void Empty() { v_.clear(); }
  T* GetData() { return v_.data(); }
  const T* GetData() const { return v_.data(); }
  T& operator[](int32 i) { return v_.at(static_cast<size_t>(i)); }
  const T& operator[](int32 i) const { return v_.at(static_cast<size_t>(i)); }
 private:
  std::vector<T> v_;
};

template <typename T>
class TSharedPtr {
 public:
  TSharedPtr() = default;
  TSharedPtr(std::nullptr_t) {}
  explicit TSharedPtr(std::shared_ptr<T> p) : p_(std::move(p)) {}
  bool IsValid() const { return p_ != nullptr; }
  T* operator->() const { return p_.get(); }
 private:
  std::shared_ptr<T> p_;
};

struct FVector {
  double X = 0, Y = 0, Z = 0;
  FVector() = default;
  FVector(double x, double y, double z) : X(x), Y(y), Z(z) {}
  static const FVector ZeroVector;
};
inline const FVector FVector::ZeroVector{0, 0, 0};

struct FQuat {
  double X = 0, Y = 0, Z = 0, W = 1;
  FQuat() = default;
  FQuat(double x, double y, double z, double w) : X(x), Y(y), Z(z), W(w) {}
};

struct FFilePath {
  FString FilePath;
};

// Logging: printf to stderr (TCHAR is char here).
enum class ELogVerbosity { Fatal, Error, Warning, Display, Log, Verbose, VeryVerbose, All };
struct FLogCategoryStub { const char* Name; };
#define DECLARE_LOG_CATEGORY_EXTERN(Name, Default, Compile) extern FLogCategoryStub Name
#define DEFINE_LOG_CATEGORY(Name) FLogCategoryStub Name{#Name}
#define DEFINE_LOG_CATEGORY_STATIC(Name, Default, Compile) static FLogCategoryStub Name{#Name}
#define UE_LOG(Category, Verbosity, Format, ...) \
  (void)(std::fprintf(stderr, "%s: %s: " Format "\n", (Category).Name, #Verbosity, ##__VA_ARGS__))

// Dynamic multicast delegates: a list of std::function (stub: AddStub).
#define DECLARE_DYNAMIC_MULTICAST_DELEGATE_OneParam(Name, T1, P1)            \
  struct Name {                                                               \
    std::vector<std::function<void(T1)>> Handlers;                            \
    void AddStub(std::function<void(T1)> f) { Handlers.push_back(std::move(f)); } \
    void Broadcast(T1 P1) const { for (const auto& h : Handlers) h(P1); }     \
  }
