// Code names in table cells (the notation page) and in the navigation (the API reference's module names) may
// break after a dot, an underscore, a comma or an opening parenthesis, so that a long name wraps between its
// parts instead of inside a word or being clipped.
document.addEventListener("DOMContentLoaded", () => {
  const escape = (s) => s.replace(/&/g, "&amp;").replace(/</g, "&lt;").replace(/>/g, "&gt;");
  for (const el of document.querySelectorAll("td code.literal span.pre, .bd-sidebar-primary code.literal span.pre")) {
    el.innerHTML = escape(el.textContent).replace(/([._,(=])/g, "$1<wbr>");
  }
});
