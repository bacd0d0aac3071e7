<?xml version="1.0"?>
<GML>
  <tag>
    <drawing>
      <stroke>
        <pt><x>0.1</x><y>0.1</y><time>0.0</time></pt>
        <pt><x>0.2</x><y>0.2</y><time>0.1</time></pt>
      </stroke>
      <stroke>
        <pt><x>0.3</x><y>0.3</y><time>0.5</time></pt>
        <pt><x>0.4</x><y>0.4</y><time>0.6</time></pt>
        <pt><x>0.5</x><y>0.5</y><time>0.