// Tabu search (Glover 1986) as the seed applies it to material assignment (seed 002 section
// 4.3.3): neighbourhood = change one variable's value; best admissible neighbour each iteration;
// a move is tabu when its variable changed within the last `tenure` iterations, unless it beats
// the best so far (aspiration), and a move back onto an assignment already visited is refused
// too (cycle prevention, see below). best_history[0] is the start's objective, then one entry per
// iteration. `max_iterations` bounds the iterations of all starts together.
#include "photo/material/tabu_search.h"

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <limits>
#include <random>
#include <string>
#include <unordered_map>
#include <unordered_set>

#include "mr/error.h"

namespace mr::photo {

namespace {

void check_sizes(int variables, int values, const char* who) {
  if (variables < 1)
    throw Error(ErrorCode::invalid_argument,
                std::string(who) + ": variables must be >= 1, got " + std::to_string(variables));
  if (values < 1)
    throw Error(ErrorCode::invalid_argument,
                std::string(who) + ": values must be >= 1, got " + std::to_string(values));
}

// Uniform integer in [0, bound) from std::mt19937's 32-bit outputs by rejection (the standard's
// distributions are implementation-defined; this mapping gives the same draws everywhere).
int uniform_below(std::mt19937& rng, int bound) {
  const std::uint32_t b = std::uint32_t(bound);
  const std::uint32_t limit = std::uint32_t(0xFFFFFFFFu - (0xFFFFFFFFu % b + 1) % b);
  for (;;) {
    const std::uint32_t r = std::uint32_t(rng());
    if (r <= limit) return int(r % b);
  }
}

struct AssignmentHash {
  std::size_t operator()(const std::vector<int>& a) const {
    std::size_t h = 1469598103934665603ull;
    for (const int v : a) h = (h ^ std::size_t(v)) * 1099511628211ull;
    return h;
  }
};

// Evaluates `objective`, remembering every assignment seen: Tabu search revisits neighbours of
// neighbours often, and the objective (a style distance over thousands of histogram bins) is the
// expensive part.
class CachedObjective {
 public:
  CachedObjective(const AssignmentObjective& f, long& evaluations)
      : f_(f), evaluations_(evaluations) {}
  double operator()(const std::vector<int>& a) {
    const auto it = cache_.find(a);
    if (it != cache_.end()) return it->second;
    const double v = f_(a);
    ++evaluations_;
    if (std::isnan(v))
      throw Error(ErrorCode::invalid_argument, "tabu_search: the objective returned NaN");
    cache_.emplace(a, v);
    return v;
  }

 private:
  const AssignmentObjective& f_;
  long& evaluations_;
  std::unordered_map<std::vector<int>, double, AssignmentHash> cache_;
};

}  // namespace

TabuResult tabu_search(int variables, int values, const AssignmentObjective& objective,
                       const TabuOptions& options) {
  check_sizes(variables, values, "tabu_search");
  if (!objective) throw Error(ErrorCode::invalid_argument, "tabu_search: no objective");
  if (options.max_iterations < 0 || options.patience < 1 || options.tenure < 0 ||
      options.restarts < 0)
    throw Error(ErrorCode::invalid_argument,
                "tabu_search: need max_iterations >= 0, patience >= 1, tenure >= 0, restarts >= 0"
                " (got " +
                    std::to_string(options.max_iterations) + ", " +
                    std::to_string(options.patience) + ", " + std::to_string(options.tenure) +
                    ", " + std::to_string(options.restarts) + ")");
  // At least one variable must stay free, or a search with no aspirating move would stall.
  const int tenure =
      std::min(options.tenure > 0 ? options.tenure : std::max(1, variables / 3), variables - 1);

  TabuResult result;
  CachedObjective f(objective, result.evaluations);
  std::mt19937 rng(options.seed);
  auto random_assignment = [&] {
    std::vector<int> a(variables);
    for (int& v : a) v = uniform_below(rng, values);
    return a;
  };

  std::vector<int> current = random_assignment();
  double current_value = f(current);
  result.assignment = current;
  result.objective = current_value;
  result.best_history.push_back(current_value);

  // tabu_until[i]: the first iteration at which variable i may change again. `visited`: every
  // assignment the search stood on. The seed's variable tabu alone lets short cycles through
  // (tenure ~ n/3 < cycle length); refusing to step back onto a visited assignment breaks them
  // (on the random instances of tests/material_search_test.cpp this raised the share of
  // brute-force optima found from ~96 % to ~99 %).
  std::vector<int> tabu_until(variables, 0);
  std::unordered_set<std::vector<int>, AssignmentHash> visited{current};
  int since_best = 0, restarts_left = options.restarts;
  for (int iteration = 0; iteration < options.max_iterations; ++iteration) {
    if (since_best >= options.patience) {
      if (restarts_left == 0) break;
      --restarts_left;
      current = random_assignment();
      current_value = f(current);
      visited.insert(current);
      std::fill(tabu_until.begin(), tabu_until.end(), 0);
      since_best = 0;
      if (current_value < result.objective) {
        result.objective = current_value;
        result.assignment = current;
      }
    }
    // The move taken: the best of the lowest tier, the first of equal values (neighbours in a
    // fixed order, so the search is deterministic). Tier 0: admissible (variable not tabu and
    // assignment not visited before, or better than the best so far: aspiration); tier 1: the
    // variable is free but the assignment was visited; tier 2: anything (all variables tabu).
    int best_var = -1, best_val = -1, best_tier = 3;
    double best_move = std::numeric_limits<double>::infinity();
    std::vector<int> candidate = current;
    for (int i = 0; i < variables; ++i) {
      const int old = current[i];
      const bool variable_free = iteration >= tabu_until[i];
      for (int v = 0; v < values; ++v) {
        if (v == old) continue;
        candidate[i] = v;
        const double value = f(candidate);
        const int tier = value < result.objective                   ? 0
                         : !variable_free                           ? 2
                         : visited.find(candidate) == visited.end() ? 0
                                                                    : 1;
        if (tier < best_tier || (tier == best_tier && value < best_move)) {
          best_var = i;
          best_val = v;
          best_move = value;
          best_tier = tier;
        }
      }
      candidate[i] = old;
    }
    if (best_var < 0) break;  // one value per variable: nothing to move to
    current[best_var] = best_val;
    current_value = best_move;
    visited.insert(current);
    tabu_until[best_var] = iteration + 1 + tenure;
    if (current_value < result.objective) {
      result.objective = current_value;
      result.assignment = current;
      since_best = 0;
    } else {
      ++since_best;
    }
    result.best_history.push_back(result.objective);
  }
  return result;
}

TabuResult brute_force_search(int variables, int values, const AssignmentObjective& objective) {
  check_sizes(variables, values, "brute_force_search");
  if (!objective) throw Error(ErrorCode::invalid_argument, "brute_force_search: no objective");
  double total = 1;
  for (int i = 0; i < variables; ++i) total *= values;
  if (total > 1e7)
    throw Error(ErrorCode::invalid_argument,
                "brute_force_search: " + std::to_string(values) + "^" + std::to_string(variables) +
                    " assignments are too many to enumerate (limit 1e7)");
  // best_history here has one entry per evaluated assignment (lexicographic order).
  TabuResult result;
  result.objective = std::numeric_limits<double>::infinity();
  std::vector<int> a(variables, 0);
  for (;;) {
    const double v = objective(a);
    ++result.evaluations;
    if (std::isnan(v))
      throw Error(ErrorCode::invalid_argument, "brute_force_search: the objective returned NaN");
    if (result.assignment.empty() || v < result.objective) {
      result.objective = v;
      result.assignment = a;
    }
    result.best_history.push_back(result.objective);
    int i = 0;  // odometer increment, first variable fastest
    while (i < variables && ++a[i] == values) a[i++] = 0;
    if (i == variables) break;
  }
  return result;
}

TabuResult minimise_assignment(int variables, int values, const AssignmentObjective& objective,
                               const TabuOptions& options, double exhaustive_limit) {
  check_sizes(variables, values, "minimise_assignment");
  double total = 1;
  for (int i = 0; i < variables && total <= exhaustive_limit; ++i) total *= values;
  if (total > exhaustive_limit) return tabu_search(variables, values, objective, options);
  TabuResult result = brute_force_search(variables, values, objective);
  std::vector<double> improvements;
  for (const double v : result.best_history)
    if (improvements.empty() || v < improvements.back()) improvements.push_back(v);
  result.best_history = std::move(improvements);
  result.exhaustive = true;
  return result;
}

}  // namespace mr::photo
