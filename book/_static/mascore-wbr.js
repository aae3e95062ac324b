// Code names in table cells (the notation page) may break after a dot, an underscore, a comma or
// an opening parenthesis, so that a long name wraps between its parts instead of inside a word.
document.addEventListener("DOMContentLoaded", () => {
  const escape = (s) => s.replace(/&/g, "&amp;").replace(/</g, "&lt;").replace(/>/g, "&gt;");
  for (const el of document.querySelectorAll("td code.literal span.pre")) {
    el.innerHTML = escape(el.textContent).replace(/([._,(=])/g, "$1<wbr>");
  }
});
