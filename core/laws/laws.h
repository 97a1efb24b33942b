#pragma once
// The material laws of the MLS solid: the one list. Each law is one file of this folder (what
// a law provides: core/mls_law.h); the scene reader's names, the stress for display, the
// blocked loops' variants and the tests take the laws from MaterialLaws below. Adding a law:
// its file, its line in MaterialLaws, its enumerator in MaterialLaw (core/scene.h) and in the
// wire's MaterialLaw (protocol/palpate.capnp); a static_assert below and
// tests/mls_forces_test.cpp ("TheLawListIsOneList") refuse the list and the enums out of step.
#include <array>
#include <cassert>
#include <string_view>
#include <tuple>
#include <type_traits>
#include <utility>

#include "core/laws/corotational.h"
#include "core/laws/linear.h"
#include "core/laws/neo_hookean.h"
#include "core/laws/stvk.h"

namespace palpate::mls {

template <class... Law>
struct LawList {
  static constexpr int size = sizeof...(Law);
};

using MaterialLaws = LawList<StVenantKirchhoff, Corotational, Linear, NeoHookean>;

namespace law_list {
template <class... Law>
constexpr bool ids_in_order(LawList<Law...>) {
  int k = 0;
  return ((static_cast<int>(Law::id) == k++) && ...);
}
template <class... Law>
constexpr auto names_of(LawList<Law...>) {
  return std::array<std::pair<std::string_view, MaterialLaw>, sizeof...(Law)>{{{Law::name, Law::id}...}};
}
template <class Body, class... Law>
decltype(auto) dispatch(MaterialLaw law, Body&& body, LawList<Law...>) {
  using First = std::tuple_element_t<0, std::tuple<Law...>>;
  using Result = decltype(body.template operator()<First>());
  if constexpr (std::is_void_v<Result>) {
    [[maybe_unused]] const bool found = ((law == Law::id ? (body.template operator()<Law>(), true) : false) || ...);
    assert(found && "a MaterialLaw without its law in MaterialLaws");
  } else {
    Result result{};
    [[maybe_unused]] const bool found =
        ((law == Law::id ? (result = body.template operator()<Law>(), true) : false) || ...);
    assert(found && "a MaterialLaw without its law in MaterialLaws");
    return result;
  }
}
}  // namespace law_list

// MaterialLaw's enumerators are the laws' positions in MaterialLaws.
static_assert(law_list::ids_in_order(MaterialLaws{}), "MaterialLaw (core/scene.h) and MaterialLaws out of step");

// The laws' names (the scene's material.law) and ids, in the list's order.
inline constexpr auto material_law_names = law_list::names_of(MaterialLaws{});

// body.template operator()<Law>() for the law `law` names; returns what it returns.
template <class Body>
decltype(auto) with_law(MaterialLaw law, Body&& body) {
  return law_list::dispatch(law, std::forward<Body>(body), MaterialLaws{});
}

}  // namespace palpate::mls
