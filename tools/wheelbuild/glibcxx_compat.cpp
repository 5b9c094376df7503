// Linked statically into the message package's libraries of a wheel build (tools/build_wheel.py).
//
// GCC 11 and newer inline a call to std::__throw_bad_array_new_length() into every std::vector
// allocation; libstdc++ exports it only from GLIBCXX_3.4.29 (GCC 11) on, while manylinux_2_28
// systems (RHEL 8 and its rebuilds) have GLIBCXX_3.4.25. Defining it here, in an archive linked
// with -Wl,--exclude-libs, keeps the symbol inside each library, which then needs nothing newer
// than manylinux_2_28 allows (what the manylinux toolchains do with libstdc++_nonshared.a).
#include <new>

namespace std {
void __throw_bad_array_new_length() { throw bad_array_new_length(); }
}  // namespace std
