#pragma once

// An extension point as one table: a Registry lists its implementations, one entry (a type) each.
// An entry has
//   static constexpr const char* kName;   the name the configuration selects it by
//   using Params = ...;                    its parameter section (parameter_spec.hpp: kSection, kDoc,
//                                          declare), read, validated and documented with the others
// and whatever the extension point's factory needs besides (see features/extractors.hpp,
// filter/filters.hpp). The table gives the names, one tuple holding every entry's section, and a
// walk over the entries in table order; nothing else lists the implementations.

#include <string>
#include <tuple>
#include <vector>

namespace mild {

template <class T>
struct RegistryEntry {
  using type = T;
};

template <class... Entries>
struct Registry {
  // Every entry's parameter section, one each.
  using Sections = std::tuple<typename Entries::Params...>;

  static std::vector<std::string> names() { return {Entries::kName...}; }

  // Calls f(RegistryEntry<E>{}) for every entry E, in table order.
  template <class F>
  static void forEach(F&& f) {
    (f(RegistryEntry<Entries>{}), ...);
  }

  // Calls f(RegistryEntry<E>{}) for the entry named `name` and returns true; false when none is.
  template <class F>
  static bool withName(const std::string& name, F&& f) {
    bool found = false;
    forEach([&](auto entry) {
      using E = typename decltype(entry)::type;
      if (!found && name == E::kName) {
        found = true;
        f(entry);
      }
    });
    return found;
  }
};

// Calls f(section) for every section of a Registry's Sections tuple (const or not), in table order.
template <class Tuple, class F>
void forEachSection(Tuple& sections, F&& f) {
  std::apply([&](auto&... section) { (f(section), ...); }, sections);
}

}  // namespace mild
