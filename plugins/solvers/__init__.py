"""Built-in solver plugins: IPOPT (CasADi and cyipopt), FSQP, SQP over qpsolvers, Uno, CasADi's other solvers,
Pyomo NL."""
